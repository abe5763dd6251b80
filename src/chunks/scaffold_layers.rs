//! Two-layer MLPs as the Scaffold-GS chunks store them (`AMLP` §6.10, `ADEF` §6.11): per MLP a
//! u16 hidden width in the chunk's header, then every weight in one zstd frame, f32 LE, MLP
//! after MLP: `W1` (hidden x inputs, row-major), `b1` (if biased), `W2` (outputs x hidden),
//! `b2` (if biased).

use crate::bytes::{zstd_compress, zstd_exact, ByteReader, PutLe};
use crate::container::ChunkType;
use crate::error::{Error, Result};
use crate::limits::Limits;
use crate::model::scaffold::{Activation, Dense, TwoLayer};

/// Widest hidden layer a reader accepts.
pub const MAX_HIDDEN: usize = 1024;

/// The fixed shape of one stored MLP.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    pub name: &'static str,
    pub inputs: usize,
    pub outputs: usize,
    pub biased: bool,
    pub output: Activation,
}

fn floats(s: &Shape, hidden: usize) -> usize {
    let b = s.biased as usize;
    hidden * s.inputs + b * hidden + s.outputs * hidden + b * s.outputs
}

/// Append the hidden widths to `head` and return the zstd frame of the weights.
pub fn encode(
    chunk: ChunkType,
    mlps: &[(&Shape, &TwoLayer)],
    head: &mut Vec<u8>,
    zstd_level: i32,
) -> Result<Vec<u8>> {
    let mut raw = Vec::new();
    for (s, m) in mlps {
        m.check(s.name, s.inputs, s.outputs, s.biased)
            .map_err(|r| Error::input(format!("{chunk}: {r}")))?;
        let h = m.first.outputs;
        if h == 0 || h > MAX_HIDDEN {
            return Err(Error::input(format!(
                "{chunk}: {} has {h} hidden units (1..={MAX_HIDDEN})",
                s.name
            )));
        }
        head.put_u16(h as u16);
        for d in [&m.first, &m.second] {
            for &w in &d.weights {
                raw.put_f32(w);
            }
            for &b in d.bias.iter().flatten() {
                raw.put_f32(b);
            }
        }
    }
    zstd_compress(&raw, zstd_level)
}

/// Read the hidden widths of `shapes` from `r`; then, after the caller has read the rest of
/// its header, [`decode_weights`] reads the frame.
pub fn read_hidden(r: &mut ByteReader, chunk: ChunkType, shapes: &[Shape]) -> Result<Vec<usize>> {
    shapes
        .iter()
        .map(|s| {
            let at = r.offset();
            let h = r.u16("hidden width")? as usize;
            if h == 0 || h > MAX_HIDDEN {
                return Err(Error::payload(
                    chunk,
                    format!("{} has {h} hidden units (1..={MAX_HIDDEN})", s.name),
                    at,
                ));
            }
            Ok(h)
        })
        .collect()
}

/// The MLPs from the zstd frame `frame` (the rest of the payload, at `at`).
pub fn decode_weights(
    frame: &[u8],
    at: u64,
    chunk: ChunkType,
    shapes: &[Shape],
    hidden: &[usize],
    limits: &Limits,
) -> Result<Vec<TwoLayer>> {
    let total: usize = shapes.iter().zip(hidden).map(|(s, &h)| floats(s, h)).sum();
    let len = 4 * total as u64;
    limits.check_alloc("MLP weights", len, at)?;
    let raw = zstd_exact(frame, len, at)?;
    let mut r = ByteReader::new(&raw, at);
    let mut out = Vec::with_capacity(shapes.len());
    for (s, &h) in shapes.iter().zip(hidden) {
        let mut dense = |inputs: usize, outputs: usize| -> Result<Dense> {
            let weights = r.f32_vec(inputs * outputs, "weights")?;
            let bias = if s.biased {
                Some(r.f32_vec(outputs, "biases")?)
            } else {
                None
            };
            if weights
                .iter()
                .chain(bias.iter().flatten())
                .any(|v| !v.is_finite())
            {
                return Err(Error::payload(
                    chunk,
                    format!("{}: weights must be finite", s.name),
                    at,
                ));
            }
            Ok(Dense {
                inputs,
                outputs,
                weights,
                bias,
            })
        };
        let first = dense(s.inputs, h)?;
        let second = dense(h, s.outputs)?;
        out.push(TwoLayer {
            first,
            second,
            output: s.output,
        });
    }
    Ok(out)
}
