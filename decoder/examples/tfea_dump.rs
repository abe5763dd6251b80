//! Write one GOP's HEVC time-feature packets as an Annex B file, for side-by-side runs with the
//! `ffmpeg` CLI: `cargo run --release -p dlgs-decoder --example tfea_dump -- FILE.dlgs GOP OUT.hevc`
//! (prints the picture size and count).

use dlgs::chunks::tfea::{self, TfeaBody};
use dlgs::container::ChunkType;
use dlgs_decoder::Decoder;

fn main() -> dlgs::Result<()> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: tfea_dump FILE.dlgs GOP OUT.hevc";
    let path = args.next().expect(usage);
    let gop: u32 = args.next().expect(usage).parse().expect(usage);
    let out = args.next().expect(usage);
    let mut dec = Decoder::open_path(&path)?;
    let scene = dec.scene().clone();
    let limits = dec.reader().limits().clone();
    let chunks = dec.reader().gop_chunks(gop)?;
    let c = chunks
        .into_iter()
        .find(|c| c.ty == ChunkType::TFEA)
        .expect("the GOP has time features");
    let p = dec.reader().payload(&c)?;
    match tfea::decode(&p, 0, &scene, &limits)? {
        TfeaBody::Hevc {
            tiling, packets, ..
        } => {
            std::fs::write(&out, packets.concat()).expect("writable output");
            println!(
                "{} pictures of {}x{} in {} packets, {} bytes -> {out}",
                tiling.keys,
                tiling.width(),
                tiling.height(),
                packets.len(),
                packets.iter().map(Vec::len).sum::<usize>()
            );
        }
        TfeaBody::Exact(_) => eprintln!("GOP {gop} stores exact features, not HEVC"),
        TfeaBody::Quantised(q) => eprintln!(
            "GOP {gop} stores features quantised to {} bits (codec 4), not HEVC",
            q.bits
        ),
    }
    Ok(())
}
