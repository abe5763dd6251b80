//! The `CSOG` payload parser directly (every layout: grid and octree positions, k-d layout,
//! coarse rotations, compact records, every grid codec and codec-5 mode), against a scene
//! header made from the first four bytes: SH degree and language (byte 0), static count (bytes
//! 1-2, little-endian), dynamic count (byte 3). The container targets reach this parser only
//! through whole files; here every mutation lands in the payload. `describe` (`dlgs info
//! --channels`) walks the same records without decoding them and must agree on whether they
//! are well formed up to the cells.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((head, body)) = data.split_first_chunk::<4>() else {
        return;
    };
    let mut s = dlgs::SceneHeader::still(u16::from_le_bytes([head[1], head[2]]) as u32, head[0] & 3);
    s.n_dynamic = head[3] as u32;
    if head[0] & 4 != 0 {
        s.lang_levels = 3;
        s.lang_dims = 3;
    }
    let decoded = dlgs::chunks::csog::decode(body, 0, &s, &dlgs::Limits::tiny());
    let described = dlgs::chunks::csog::describe(body, 0, &s);
    // Whatever decodes is also described (the converse need not hold: describe never decodes
    // cells, and decode may refuse an allocation under the tiny limits).
    assert!(decoded.is_err() || described.is_ok());
});
