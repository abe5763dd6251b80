//! `AMLP`: the view-dependent MLPs of a Scaffold-GS GOP (format-spec §6.10): opacity, colour,
//! covariance and, with language, language, each `54 -> hidden -> out` with biases.

use super::scaffold_layers::{self as layers, Shape};
use crate::bytes::{ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::scaffold::{Activation, ScaffoldMlps, LANG_DIM, N_OFFSETS, VIEW_INPUTS};

const FLAG_LANGUAGE: u8 = 1;

fn shapes(language: bool) -> Vec<Shape> {
    let s = |name, outputs, output| Shape {
        name,
        inputs: VIEW_INPUTS,
        outputs,
        biased: true,
        output,
    };
    let mut v = vec![
        s(
            "opacity",
            if language { 2 * N_OFFSETS } else { N_OFFSETS },
            Activation::Tanh,
        ),
        s("color", 3 * N_OFFSETS, Activation::Sigmoid),
        s("cov", 7 * N_OFFSETS, Activation::Identity),
    ];
    if language {
        v.push(s("language", LANG_DIM * N_OFFSETS, Activation::Identity));
    }
    v
}

/// Whether the scene carries language (then the language MLP is required).
fn scene_language(scene: &SceneHeader) -> bool {
    scene.lang_levels > 0
}

pub fn encode(m: &ScaffoldMlps, scene: &SceneHeader, zstd_level: i32) -> Result<Vec<u8>> {
    let language = scene_language(scene);
    if m.language.is_some() != language {
        return Err(Error::input(format!(
            "the scene {} language but the view MLPs {} a language MLP",
            if language { "has" } else { "has no" },
            if m.language.is_some() {
                "have"
            } else {
                "have no"
            }
        )));
    }
    let sh = shapes(language);
    let mut list = vec![(&sh[0], &m.opacity), (&sh[1], &m.color), (&sh[2], &m.cov)];
    if let Some(l) = &m.language {
        list.push((&sh[3], l));
    }
    let mut p = Vec::new();
    p.put_u8(if language { FLAG_LANGUAGE } else { 0 });
    p.extend_from_slice(&[0, 0, 0]);
    let frame = layers::encode(ChunkType::AMLP, &list, &mut p, zstd_level)?;
    p.extend_from_slice(&frame);
    Ok(p)
}

pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<ScaffoldMlps> {
    let mut r = ByteReader::new(p, offset);
    let flags = r.u8("flags")?;
    if flags & !FLAG_LANGUAGE != 0 || (flags & FLAG_LANGUAGE != 0) != scene_language(scene) {
        return Err(Error::payload(
            ChunkType::AMLP,
            format!("flags {flags:#x}: bit 0 must say whether the scene has language"),
            offset,
        ));
    }
    r.take(3, "reserved")?;
    let sh = shapes(scene_language(scene));
    let hidden = layers::read_hidden(&mut r, ChunkType::AMLP, &sh)?;
    let at = r.offset();
    let mut m =
        layers::decode_weights(r.rest(), at, ChunkType::AMLP, &sh, &hidden, limits)?.into_iter();
    let mut next = || m.next().expect("one MLP per shape");
    Ok(ScaffoldMlps {
        opacity: next(),
        color: next(),
        cov: next(),
        language: scene_language(scene).then(&mut next),
    })
}
