//! The readers of the reference's HAC (Scaffold-GS) run files in `dlgs-ingest` (`hac/`):
//! `anchor.npy`, `patched_infos.npy` (a pickled object array), binary grids (`hash.b`,
//! `ntc_*.b`) and Gaussian-coded attribute files (`feat|scaling|offsets_{s}_0.b`, with the
//! re-encode check and a short repair search).
#![no_main]
use dlgs_ingest::hac::{bitstream, gaussian, npy};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let (sel, body) = data.split_first().unwrap_or((&0, &[]));
    match sel % 4 {
        0 => {
            let _ = npy::parse_anchor_npy(body, "anchor.npy");
        }
        1 => {
            let _ = npy::parse_patched_infos(body, "patched_infos.npy");
        }
        2 => {
            let _ = bitstream::decode_binary(body, 20_000, "hash.b");
        }
        _ => {
            // 4 anchors x 5 channels, a unit Gaussian each, steps of 1.
            let (mean, scale) = (vec![0.0f32; 20], vec![1.0f32; 20]);
            let q = vec![1.0f32; 4];
            let _ = gaussian::decode_gaussian(body, 5, &mean, &scale, &q, &q, 2, "feat_0_0.b");
        }
    }
});
