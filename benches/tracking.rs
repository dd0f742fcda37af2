//! Criterion benchmarks of the hot paths: one iteration of ICLK, FCLK and ESM (SSD, homography,
//! 50x50) on a real texture, and the pre-processing of a tracker's region. The whole-tracker
//! figures are in `regtrack bench`.

use criterion::{Criterion, criterion_group, criterion_main};
use regtrack::geometry::Quad;
use regtrack::imaging::{Preprocessor, gaussian_kernel, load_gray};
use regtrack::observe::NoObserver;
use regtrack::tracker::{FrameInput, Tracker, TrackerSpec};
use std::hint::black_box;
use std::path::Path;

fn bench(c: &mut Criterion) {
    let img = load_gray(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/textures/skimage_coffee.png"),
    )
    .expect("bundled texture");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let start = Quad::from_array([251.5, 149.0, 351.0, 151.2, 349.0, 250.8, 248.9, 249.0]);
    let smoothed = regtrack::imaging::gaussian_blur(&img, &gaussian_kernel(5, 3.0));
    for sm in ["iclk", "fclk", "esm"] {
        let mut spec = TrackerSpec::from_names(sm, "ssd", "homography").expect("spec");
        spec.params.max_iters = 1;
        let mut t = Tracker::new(&spec).expect("tracker");
        t.initialize(FrameInput::Smoothed(&smoothed), &truth)
            .expect("init");
        c.bench_function(&format!("{sm}_ssd_homography one iteration"), |b| {
            b.iter(|| {
                t.set_corners(&start).expect("corners");
                black_box(t.update(FrameInput::Smoothed(&smoothed), &mut NoObserver))
            })
        });
    }
    let mut pre = Preprocessor::new(gaussian_kernel(5, 3.0));
    c.bench_function("preprocess 150x150 region (5x5 Gaussian)", |b| {
        b.iter(|| pre.process(black_box(&img), 225.0, 125.0, 375.0, 275.0))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
