//! Canonical-state decoding on real data: the `CSOG` payload of the real plant scene (113,648
//! Gaussians) at `high`, with grid positions (layout 0), octree positions (in compact records:
//! layout 4 since format 1.14) and octree positions with coarse rotations (the default; also as
//! `dlgs encode --fast-decode` writes it, without codec 5's mixed modes), and a GENERATED binary
//! voxel residual field (`RNTC`, the reference's shapes; no trained DLGStream model exists here)
//! applied to that scene, 1 and 2 threads. Also each codec-5 mode on one real channel (the
//! plant's SH DC blue at `high`, given green and red), 1 thread: what the mixed modes (5 and 6,
//! since format 1.13) cost against the trees.
//! `cargo bench -p dlgs-decoder --bench canonical`

use criterion::{criterion_group, criterion_main, Criterion};
use dlgs::chunks::csog::{self, QuantBits, RotationCoarsening};
use dlgs::container::SceneHeader;
use dlgs::model::ntc::NtcConfig;
use dlgs::model::Canonical;
use dlgs::Limits;
use dlgs_encoder::grid_sort::{grid_order, permute, SortSpec};
use dlgs_testkit::bench_scenes::plant;
use dlgs_testkit::synth::synth_ntc;

fn bench(c: &mut Criterion) {
    let g = plant();
    let sorted = permute(&g, &grid_order(&g, SortSpec::DEFAULT));
    let canon = Canonical::from_static(sorted);
    let payload = csog::encode(&canon, &QuantBits::HIGH, 9).unwrap();
    let part = [(g.clone(), QuantBits::HIGH)];
    let octree_payload = |rotation_coarsening, mixed_margin| {
        let gop = csog::PartedGop {
            static_parts: &part,
            static_weight: None,
            dynamics: &canon.dynamics,
            dynamic_bits: &QuantBits::HIGH,
            rotation_coarsening,
            compact_records: true,
            mixed_margin,
        };
        csog::encode_octree(&gop, 9).unwrap().0
    };
    let default = Some(dlgs::chunks::csog::grid_codecs::MIXED_MARGIN);
    let octree = octree_payload(None, default);
    let coarse = octree_payload(Some(RotationCoarsening::DEFAULT), default);
    // `dlgs encode --fast-decode`: the default layout without codec 5's mixed modes.
    let fast = octree_payload(Some(RotationCoarsening::DEFAULT), None);
    let scene = SceneHeader::still(g.len() as u32, g.sh_degree);
    let field = synth_ntc(
        &canon,
        &mut fastrand::Rng::with_seed(7),
        0.01,
        NtcConfig::default(),
    );
    let mut group = c.benchmark_group("canonical_plant_113k");
    group.sample_size(20);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        group.bench_function(format!("csog_high_decode/{threads}t"), |b| {
            b.iter(|| {
                pool.install(|| csog::decode(&payload, 0, &scene, &Limits::default()))
                    .unwrap()
            })
        });
        group.bench_function(format!("csog_high_octree_decode/{threads}t"), |b| {
            b.iter(|| {
                pool.install(|| csog::decode(&octree, 0, &scene, &Limits::default()))
                    .unwrap()
            })
        });
        group.bench_function(format!("csog_high_coarse_decode/{threads}t"), |b| {
            b.iter(|| {
                pool.install(|| csog::decode(&coarse, 0, &scene, &Limits::default()))
                    .unwrap()
            })
        });
        group.bench_function(format!("csog_high_fast_decode/{threads}t"), |b| {
            b.iter(|| {
                pool.install(|| csog::decode(&fast, 0, &scene, &Limits::default()))
                    .unwrap()
            })
        });
        group.bench_function(format!("rntc_apply/{threads}t"), |b| {
            b.iter(|| pool.install(|| field.apply(&canon)).unwrap())
        });
    }
    group.finish();
    codec5_modes(c, &canon.statics);
}

/// Decode time of one channel in each codec-5 mode (single thread: a channel is one stream).
fn codec5_modes(c: &mut Criterion, g: &dlgs::model::Gaussians) {
    use dlgs::bytes::ByteReader;
    use dlgs::chunks::csog::grid_codecs::{
        adaptive_decode as decode, adaptive_encode as encode, AdaptiveMode as Mode,
    };
    let set = csog::quantise_set(g, &QuantBits::HIGH);
    // Channels: position 3, log-scale 3, rotation index and 3 components, opacity, then DC.
    let dc = 11;
    let cells = |j: usize| (set.channels[j].3.as_slice(), set.channels[j].0);
    let (q, bits) = cells(dc + 2);
    let (prev, prev2) = (Some(cells(dc + 1)), Some(cells(dc)));
    let width = csog::grid_width(q.len());
    let mut group = c.benchmark_group("codec5_plant_dc_blue");
    group.sample_size(20);
    for (name, mode) in [
        ("tree", Mode::Tree),
        ("tree_given_previous_4", Mode::TreeGivenPrevious(4)),
        ("mixed_0", Mode::Mixed(0)),
        ("mixed_4", Mode::Mixed(4)),
        ("mixed_two_4_2", Mode::MixedTwo(4, 2)),
    ] {
        let data = encode(q, prev, prev2, width, bits, mode).unwrap();
        println!("{name}: {} bytes", data.len());
        group.bench_function(name, |b| {
            b.iter(|| decode(ByteReader::new(&data, 0), q.len(), width, bits, prev, prev2).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
