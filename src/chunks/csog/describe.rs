//! Where a `CSOG` payload's bytes go, record by record (`dlgs info --channels`).

use super::channels::channels;
use super::records::{layout_of, read_parts, read_set, Record, SetForm, SetRecords};
use crate::bytes::ByteReader;
use crate::chunks::csog::grid_coder::GridCodec;
use crate::container::ChunkType;
use crate::container::SceneHeader;
use crate::error::Result;
use crate::model::Gaussians;
use crate::Error;

/// One record of a `CSOG` payload: what it holds, how it is coded and how many bytes its data
/// takes (for `dlgs info --channels`). Record heads, ranges and counts are not in `bytes`.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RecordSummary {
    /// `"static"` or `"dynamic"`.
    pub set: &'static str,
    pub part: usize,
    /// Gaussians in the part.
    pub gaussians: usize,
    /// The channel, e.g. `"log_scale y"`, `"sh 1 g"`; octree positions are one record.
    pub channel: String,
    /// The channel's attribute as `dlgs encode --bits` names it.
    pub attribute: &'static str,
    pub bits: u8,
    /// Codec and, for codec 5, its mode (§6.5.3), or `"octree"` (§6.5.5).
    pub coding: String,
    pub bytes: usize,
}

/// Where the bytes of a `CSOG` payload go, record by record.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CsogSummary {
    pub layout: u8,
    pub payload_bytes: usize,
    pub records: Vec<RecordSummary>,
}

fn coding_name(r: &Record) -> String {
    match r.codec {
        GridCodec::Constant => "constant (codec 0)".into(),
        GridCodec::Zstd => "zstd (codec 1)".into(),
        GridCodec::Predictive => "predictive (codec 2)".into(),
        GridCodec::Histogram => "histogram (codec 3)".into(),
        GridCodec::HistogramDelta => "histogram of the difference (codec 4)".into(),
        GridCodec::Adaptive => match r.mode() {
            Some(m) => format!("adaptive (codec 5), {}", m.describe()),
            None => "adaptive (codec 5), unknown mode".into(),
        },
    }
}

/// Read a `CSOG` payload's records without decoding them (no cells are allocated): which
/// channel each holds, its bits, codec and bytes. Errors as [`decode`] for what it reads.
pub fn describe(p: &[u8], offset: u64, scene: &SceneHeader) -> Result<CsogSummary> {
    let mut r = ByteReader::new(p, offset);
    let at = r.offset();
    let layout = r.u8("CSOG layout version")?;
    let kinds = channels(&Gaussians::new(scene.sh_degree, scene.lang_width()));
    let (ns, nd) = (scene.n_static as usize, scene.n_dynamic as usize);
    let mut records = Vec::new();
    let mut summarise = |set: &'static str, part: usize, n: usize, s: SetRecords| {
        let row = |channel, attribute, bits, coding, bytes| RecordSummary {
            set,
            part,
            gaussians: n,
            channel,
            attribute,
            bits,
            coding,
            bytes,
        };
        if let Some(t) = &s.tree {
            let bytes = t.stored_len;
            records.push(row(
                "positions".into(),
                "position",
                t.bits,
                "octree".into(),
                bytes,
            ));
        }
        for rec in &s.records[s.first..] {
            let (name, attribute) = (rec.kind.name(), rec.kind.attribute());
            records.push(row(
                name,
                attribute,
                rec.bits,
                coding_name(rec),
                rec.stored_len,
            ));
        }
    };
    match layout_of(layout, at)? {
        None => {
            for (set, n) in [("static", ns), ("dynamic", nd)] {
                summarise(
                    set,
                    0,
                    n,
                    read_set(&mut r, n, &kinds, SetForm::Grid, false)?,
                );
            }
        }
        Some((form, compact)) => {
            for (set, n, form) in [("static", ns, form), ("dynamic", nd, SetForm::Grid)] {
                let mut part = 0;
                read_parts(&mut r, n, compact, |r, np| {
                    summarise(set, part, np, read_set(r, np, &kinds, form, compact)?);
                    part += 1;
                    Ok(())
                })?;
            }
        }
    }
    if r.remaining() != 0 {
        return Err(Error::payload(
            ChunkType::CSOG,
            format!("{} bytes after the last channel", r.remaining()),
            r.offset(),
        ));
    }
    Ok(CsogSummary {
        layout,
        payload_bytes: p.len(),
        records,
    })
}
