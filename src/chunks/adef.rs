//! `ADEF`: the anchor deformation of a Scaffold-GS GOP (format-spec §6.11): the normalisation
//! box and the four bias-free MLPs (`xyz` 19 -> h -> 3, `feature` 16 -> h -> 50, `offsets`
//! 16 -> h -> 30, `scaling` 16 -> h -> 6).

use super::scaffold_layers::{self as layers, Shape};
use crate::bytes::{ByteReader, PutLe};
use crate::container::ChunkType;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::scaffold::{
    Activation, AnchorDeformMlps, AnchorDeformation, FEAT_DIM, N_OFFSETS, SCALING_DIM,
    TIME_CHANNELS,
};

fn shapes() -> [Shape; 4] {
    let s = |name, inputs, outputs| Shape {
        name,
        inputs,
        outputs,
        biased: false,
        output: Activation::Identity,
    };
    [
        s("xyz", TIME_CHANNELS + 3, 3),
        s("feature", TIME_CHANNELS, FEAT_DIM),
        s("offsets", TIME_CHANNELS, 3 * N_OFFSETS),
        s("scaling", TIME_CHANNELS, SCALING_DIM),
    ]
}

fn check_box(lo: [f32; 3], hi: [f32; 3]) -> std::result::Result<(), String> {
    for a in 0..3 {
        if !(lo[a].is_finite() && hi[a].is_finite() && hi[a] > lo[a]) {
            return Err(format!(
                "box axis {a}: [{}, {}] must be finite with max > min",
                lo[a], hi[a]
            ));
        }
    }
    Ok(())
}

pub fn encode(d: &AnchorDeformation, zstd_level: i32) -> Result<Vec<u8>> {
    check_box(d.bound_min, d.bound_max).map_err(|e| Error::input(format!("ADEF: {e}")))?;
    let mut p = Vec::new();
    for v in d.bound_min.iter().chain(&d.bound_max) {
        p.put_f32(*v);
    }
    let sh = shapes();
    let m = &d.mlps;
    let list = [
        (&sh[0], &m.position),
        (&sh[1], &m.feature),
        (&sh[2], &m.offsets),
        (&sh[3], &m.scaling),
    ];
    let frame = layers::encode(ChunkType::ADEF, &list, &mut p, zstd_level)?;
    p.extend_from_slice(&frame);
    Ok(p)
}

pub fn decode(p: &[u8], offset: u64, limits: &Limits) -> Result<AnchorDeformation> {
    let mut r = ByteReader::new(p, offset);
    let mut v = [0f32; 6];
    for x in &mut v {
        *x = r.f32("box")?;
    }
    let (lo, hi) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
    check_box(lo, hi).map_err(|e| Error::payload(ChunkType::ADEF, e, offset))?;
    let sh = shapes();
    let hidden = layers::read_hidden(&mut r, ChunkType::ADEF, &sh)?;
    let at = r.offset();
    let mut m =
        layers::decode_weights(r.rest(), at, ChunkType::ADEF, &sh, &hidden, limits)?.into_iter();
    let mut next = || m.next().expect("one MLP per shape");
    Ok(AnchorDeformation {
        bound_min: lo,
        bound_max: hi,
        mlps: AnchorDeformMlps {
            position: next(),
            feature: next(),
            offsets: next(),
            scaling: next(),
        },
    })
}
