//! The TFEA, MLPW and LAED payload parsers directly, against a fixed dynamic scene header
//! (and the HEVC slice-header reader of `TFEA` streams, `dlgs_decoder::hevc::display_order`;
//! codec 4's dequantisation).
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut s = dlgs::SceneHeader::still(0, 1);
    s.n_dynamic = 1;
    s.time_channels = 16;
    s.gop_length = 60;
    s.key_interval = 10;
    s.frame_count = 60;
    s.lang_levels = 3;
    s.lang_dims = 3;
    let limits = dlgs::Limits::tiny();
    let (sel, body) = data.split_first().unwrap_or((&0, &[]));
    if sel % 3 == 2 {
        if let Ok(ld) = dlgs::chunks::laed::decode(body, 0, &s, &limits) {
            let mut out = vec![0.0; ld.embed_dims()];
            ld.decode_one(&vec![0.25; ld.input_dims()], &mut out);
        }
    } else if sel & 1 == 0 {
        let tfea = dlgs::chunks::tfea::decode(body, 0, &s, &limits);
        if let Ok(dlgs::chunks::tfea::TfeaBody::Quantised(q)) = &tfea {
            assert_eq!(q.columns().len(), q.n * q.keys * q.channels);
            let _ = q.features();
        }
        if let Ok(dlgs::chunks::tfea::TfeaBody::Hevc { tiling, ranges, reference, packets, intra }) = tfea {
            if intra {
                // Codec 3: every packet decodes alone, as a seek does it.
                for p in &packets {
                    let _ = dlgs_video::decode_gray12(&[p.as_slice()], tiling.width() as u32, tiling.height() as u32, 1);
                }
            }
            // The output order read from the slice headers (what a prefix decode relies on):
            // `None` or a permutation of the packets, never a panic.
            if let Some(order) = dlgs_decoder::hevc::display_order(&packets) {
                let mut seen = vec![false; packets.len()];
                for &d in &order {
                    assert!(!std::mem::replace(&mut seen[d], true), "a permutation");
                }
            }
            let refs: Vec<&[u8]> = packets.iter().map(|p| p.as_slice()).collect();
            if let Ok(v) = dlgs_video::decode_gray12(&refs, tiling.width() as u32, tiling.height() as u32, tiling.keys) {
                let _ = match reference {
                    Some(r) => dlgs::chunks::tfea::untile_reference(&v.frames, &tiling, r),
                    None => dlgs::chunks::tfea::untile(&v.frames, &tiling, &ranges),
                };
            }
        }
    } else {
        let _ = dlgs::chunks::mlpw::decode(body, 0, &s, &limits);
    }
});
