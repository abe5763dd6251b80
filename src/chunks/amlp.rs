//! `AMLP`: the view-dependent MLPs of a Scaffold-GS GOP (format-spec §6.10): opacity, colour,
//! covariance and, with language, language, each `54 -> hidden -> out` with biases; or, in a
//! GOP with a reference GOP (since 1.17), the language MLP alone, the others inherited.

use super::scaffold_layers::{self as layers, Shape};
use crate::bytes::{ByteReader, PutLe};
use crate::container::{ChunkType, SceneHeader};
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::scaffold::{
    Activation, ScaffoldMlps, TwoLayer, LANG_DIM, N_OFFSETS, VIEW_INPUTS,
};

const FLAG_LANGUAGE: u8 = 1;
/// Since 1.17: only the language MLP is stored; opacity, colour and cov are the reference
/// GOP's.
const FLAG_LANGUAGE_ONLY: u8 = 2;

/// What an `AMLP` payload holds.
#[derive(Debug, Clone, PartialEq)]
pub enum AmlpPayload {
    /// Every view MLP.
    Full(Box<ScaffoldMlps>),
    /// The language MLP alone (flags bit 1); the others are the reference GOP's.
    LanguageOnly(TwoLayer),
}

impl AmlpPayload {
    /// The GOP's view MLPs, given its reference GOP's (`None` for an intra GOP).
    pub fn resolve(self, reference: Option<&ScaffoldMlps>) -> Option<ScaffoldMlps> {
        match self {
            AmlpPayload::Full(m) => Some(*m),
            AmlpPayload::LanguageOnly(l) => reference.map(|r| ScaffoldMlps {
                language: Some(l),
                ..r.clone()
            }),
        }
    }
}

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

/// A language-only `AMLP` (flags 3, since 1.17): `language` replaces the reference GOP's
/// language MLP; valid only in a GOP with a reference GOP of a scene with language.
pub fn encode_language_only(
    language: &TwoLayer,
    scene: &SceneHeader,
    zstd_level: i32,
) -> Result<Vec<u8>> {
    if !scene_language(scene) {
        return Err(Error::input(
            "a language-only AMLP in a scene without language",
        ));
    }
    let sh = shapes(true);
    let mut p = Vec::new();
    p.put_u8(FLAG_LANGUAGE | FLAG_LANGUAGE_ONLY);
    p.extend_from_slice(&[0, 0, 0]);
    let frame = layers::encode(ChunkType::AMLP, &[(&sh[3], language)], &mut p, zstd_level)?;
    p.extend_from_slice(&frame);
    Ok(p)
}

/// Decode the `AMLP` of an intra GOP: every view MLP (a language-only payload is `Payload`).
pub fn decode(p: &[u8], offset: u64, scene: &SceneHeader, limits: &Limits) -> Result<ScaffoldMlps> {
    match decode_any(p, offset, scene, limits)? {
        AmlpPayload::Full(m) => Ok(*m),
        AmlpPayload::LanguageOnly(_) => Err(Error::payload(
            ChunkType::AMLP,
            "a language-only AMLP (flags bit 1) in a GOP without a reference GOP",
            offset,
        )),
    }
}

/// Decode an `AMLP` payload, full or language-only (the latter only means something in a GOP
/// with a reference GOP; the caller checks).
pub fn decode_any(
    p: &[u8],
    offset: u64,
    scene: &SceneHeader,
    limits: &Limits,
) -> Result<AmlpPayload> {
    let mut r = ByteReader::new(p, offset);
    let flags = r.u8("flags")?;
    let language = scene_language(scene);
    let only = flags & FLAG_LANGUAGE_ONLY != 0;
    if flags & !(FLAG_LANGUAGE | FLAG_LANGUAGE_ONLY) != 0
        || (flags & FLAG_LANGUAGE != 0) != language
        || (only && !language)
    {
        return Err(Error::payload(
            ChunkType::AMLP,
            format!(
                "flags {flags:#x}: bit 0 must say whether the scene has language, bit 1 \
                 (language only) needs language"
            ),
            offset,
        ));
    }
    r.take(3, "reserved")?;
    let sh = if only {
        shapes(true).split_off(3)
    } else {
        shapes(language)
    };
    let hidden = layers::read_hidden(&mut r, ChunkType::AMLP, &sh)?;
    let at = r.offset();
    let mut m =
        layers::decode_weights(r.rest(), at, ChunkType::AMLP, &sh, &hidden, limits)?.into_iter();
    let mut next = || m.next().expect("one MLP per shape");
    if only {
        return Ok(AmlpPayload::LanguageOnly(next()));
    }
    Ok(AmlpPayload::Full(Box::new(ScaffoldMlps {
        opacity: next(),
        color: next(),
        cov: next(),
        language: language.then(&mut next),
    })))
}
