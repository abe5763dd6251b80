//! The HAC bitstream decoder (`dlgs_ingest::hac`) against the fixture in
//! `fixtures/scaffold_run` (bitstreams written by `scripts/scaffold_fixture.py` with torch and
//! torchac) and the tensors its own decoder produced (`reference_decode/gop{0,1}.safetensors`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use dlgs_ingest::hac::{self, bitstream, npy, HacGop, HacLimits};
use dlgs_ingest::IngestError;
use safetensors::{Dtype, SafeTensors};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/scaffold_run")
}

fn gop_dir(g: usize) -> PathBuf {
    fixture().join(format!("gop{g}_fixture/compression/best"))
}

struct St(Vec<u8>);

impl St {
    fn load(name: &str) -> Self {
        St(std::fs::read(fixture().join("reference_decode").join(name)).unwrap())
    }
    fn raw(&self, name: &str) -> (Dtype, Vec<u8>) {
        let st = SafeTensors::deserialize(&self.0).unwrap();
        let t = st
            .tensor(name)
            .unwrap_or_else(|_| panic!("no tensor {name}"));
        (t.dtype(), t.data().to_vec())
    }
    fn f32s(&self, name: &str) -> Vec<f32> {
        let (d, b) = self.raw(name);
        assert_eq!(d, Dtype::F32, "{name}");
        b.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }
    fn i32s(&self, name: &str) -> Vec<i32> {
        let (d, b) = self.raw(name);
        assert_eq!(d, Dtype::I32, "{name}");
        b.chunks_exact(4)
            .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }
    /// `np.packbits` bits, MSB first.
    fn bits(&self, name: &str, n: usize) -> Vec<bool> {
        let (_, b) = self.raw(name);
        (0..n).map(|i| b[i / 8] >> (7 - i % 8) & 1 == 1).collect()
    }
}

/// (values that differ in bits, max |difference|).
fn compare(name: &str, ours: &[f32], reference: &[f32]) -> (usize, f32) {
    assert_eq!(ours.len(), reference.len(), "{name}: length");
    let mut differing = 0;
    let mut max = 0f32;
    for (a, b) in ours.iter().zip(reference) {
        if a.to_bits() != b.to_bits() {
            differing += 1;
            max = max.max((a - b).abs());
        }
    }
    println!(
        "{name}: {differing} of {} values differ, max |diff| {max:e}",
        ours.len()
    );
    (differing, max)
}

fn gop0() -> HacGop {
    hac::read_gop(&gop_dir(0), None, HacLimits::default()).unwrap()
}

#[test]
fn gop0_decodes_to_the_reference_tensors() {
    let t0 = Instant::now();
    let g = gop0();
    println!("GOP 0 decode: {:.3} s", t0.elapsed().as_secs_f64());
    let r = St::load("gop0.safetensors");
    let n = 2400;
    assert_eq!(g.anchors.len(), n);
    assert_eq!(g.n_static, 1845);
    let q: Vec<i32> = g
        .quantized
        .iter()
        .flat_map(|v| v.map(|x| x as i32))
        .collect();
    assert_eq!(q, r.i32s("anchor_quantized"));
    assert_eq!(g.bound_min.to_vec(), r.f32s("x_bound_min"));
    assert_eq!(g.bound_max.to_vec(), r.f32s("x_bound_max"));
    let pos: Vec<f32> = g.anchors.positions.iter().flatten().copied().collect();
    assert_eq!(compare("anchor", &pos, &r.f32s("anchor")).0, 0);
    let nh = hac::context::hash_bits();
    assert_eq!(nh, 1_766_272);
    assert!(g.hash_bits == r.bits("hash_bits_packed", nh), "hash.b bits");

    let ctx = g.context.as_ref().unwrap();
    for (k, name) in ["feat", "scaling", "offsets"].into_iter().enumerate() {
        compare(
            &format!("mean_{name}"),
            &ctx[k].mean,
            &r.f32s(&format!("mean_{name}")),
        );
        compare(
            &format!("scale_{name}"),
            &ctx[k].scale,
            &r.f32s(&format!("scale_{name}")),
        );
        compare(
            &format!("Q_{name}"),
            &ctx[k].q,
            &r.f32s(&format!("Q_{name}")),
        );
    }
    compare("feat", &g.anchors.features, &r.f32s("feat"));
    compare("scaling", &g.anchors.log_scalings, &r.f32s("scaling"));
    compare("offsets", &g.anchors.offsets, &r.f32s("offsets"));
}
