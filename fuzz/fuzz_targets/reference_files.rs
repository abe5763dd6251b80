//! The readers of the reference implementation's files (`dlgs encode RUN_DIR`) on arbitrary
//! bytes: the first byte picks the reader, the rest is the file. None may panic, hang or
//! allocate without bound; a damaged file is an `IngestError`.
#![no_main]
use libfuzzer_sys::fuzz_target;

use dlgs_ingest::{csv, jxl, latents, pickle, torch};

fuzz_target!(|data: &[u8]| {
    let Some((&which, file)) = data.split_first() else {
        return;
    };
    match which % 5 {
        0 => {
            let _ = pickle::parse(file);
        }
        1 => {
            // offset_compressed.pkl: pickle + legacy storages + the torchac range decoder.
            let _ = latents::read(file, "fuzz");
        }
        2 => {
            // mlp_*.pth / model.pth: zip + pickle + storages.
            let _ = torch::read_zip_state_dict(std::io::Cursor::new(file), "fuzz");
        }
        3 => {
            if let Ok(text) = std::str::from_utf8(file) {
                let _ = csv::parse(text, "fuzz");
            }
        }
        _ => {
            let _ = jxl::decode(file, "fuzz");
        }
    }
});
