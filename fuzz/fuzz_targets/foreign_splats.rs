//! PLY, .splat, SPZ and SOG (zip of WebP) readers on arbitrary bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let _ = dlgs::interop::ply::read_ply(data, &dlgs::Limits::tiny());
    let _ = dlgs::interop::splat::read_splat(data, &dlgs::Limits::tiny());
    let _ = dlgs::interop::spz::read_spz(data, &dlgs::Limits::tiny());
    let _ = dlgs::interop::sog::read_sog(data, &dlgs::Limits::tiny());
});
