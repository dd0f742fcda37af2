//! Criterion benchmarks of the hot paths: one iteration of ICLK, FCLK and ESM (the search
//! method's `iterate` alone, SSD and ZNCC on homography and affine, MI and CCRE on homography,
//! 50x50) on a real texture, the
//! stages of an iteration, the pre-processing of a tracker's region, one frame of the sampling
//! methods (PF-1000 on one thread and on every core: its target is 200 frames/s, 5 ms), and the many-patch tracker's frame (its time divided by the patches is the cost of
//! one patch update). The whole-tracker figures are in `regtrack bench`.

use criterion::{Criterion, criterion_group, criterion_main};
use regtrack::geometry::Quad;
use regtrack::imaging::{Preprocessor, gaussian_kernel, load_gray};
use regtrack::observe::NoObserver;
use regtrack::tracker::{FrameInput, RegistrationTracker, Tracker, TrackerSpec, VisualTracker};
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
    // One update limited to one iteration, from the same start each time (a whole frame:
    // the loss checks included).
    let one_iteration = |c: &mut Criterion, spec: &TrackerSpec| {
        let mut one = spec.clone();
        one.set_param("max_iters", "1").expect("param");
        let mut t = Tracker::new(&one).expect("tracker");
        t.initialize(FrameInput::Smoothed(&smoothed), &truth)
            .expect("init");
        c.bench_function(
            &format!("{} one frame of one iteration", one.label()),
            |b| {
                b.iter(|| {
                    t.set_corners(&start).expect("corners");
                    black_box(t.update(FrameInput::Smoothed(&smoothed), &mut NoObserver))
                })
            },
        );
    };
    // The search method's iteration alone, from one of two starts in turn (the AMs that keep
    // the statistics of the last patch, MI and CCRE, would otherwise skip them).
    let start2 = Quad::from_array([249.2, 151.0, 350.1, 148.8, 351.3, 249.5, 250.4, 251.1]);
    let view = smoothed.view();
    let mut g = c.benchmark_group("iteration");
    let cases = ["ssd", "zncc"]
        .into_iter()
        .flat_map(|am| [(am, "homography"), (am, "affine")])
        .chain([("mi", "homography"), ("ccre", "homography")]);
    for (am, ssm) in cases {
        for sm in ["iclk", "fclk", "esm"] {
            let spec = TrackerSpec::from_names(sm, am, ssm).expect("spec");
            let mut t = RegistrationTracker::new(spec.registration().expect("registration"))
                .expect("tracker");
            t.initialize(FrameInput::Smoothed(&smoothed), &truth)
                .expect("init");
            t.set_corners(&start2).expect("corners");
            let other = t.context().params();
            t.set_corners(&start).expect("corners");
            let (mut ctx, mut method) = t.into_parts();
            let starts = [ctx.params(), other];
            let mut turn = 0;
            g.bench_function(format!("{sm}_{am}_{ssm}"), |b| {
                b.iter(|| {
                    turn ^= 1;
                    ctx.set_params(starts[turn]);
                    method.start_frame(&mut ctx);
                    black_box(method.iterate(&mut ctx, black_box(&view)).expect("step"))
                })
            });
        }
    }
    g.finish();
    // The stages of one iteration, on the context of a built tracker.
    let spec = TrackerSpec::from_names("fclk", "ssd", "homography").expect("spec");
    let mut t =
        RegistrationTracker::new(spec.registration().expect("registration")).expect("tracker");
    t.initialize(FrameInput::Smoothed(&smoothed), &truth)
        .expect("init");
    let mut ctx = t.into_context();
    let p = ctx.params();
    let mut g = c.benchmark_group("stage");
    g.bench_function("warp_grid", |b| b.iter(|| ctx.warp_grid(black_box(&p))));
    g.bench_function("sample values", |b| {
        b.iter(|| ctx.work_mut().sample(black_box(&view), false))
    });
    g.bench_function("sample values+gradients", |b| {
        b.iter(|| ctx.work_mut().sample(black_box(&view), true))
    });
    g.bench_function("warped_gradient", |b| {
        b.iter(|| {
            ctx.work_mut().sample(&view, true);
            ctx.warped_gradient(black_box(&p))
        })
    });
    // Fresh, finite gradients for the next stages (the loop above applied them once more).
    ctx.work_mut().sample(&view, true);
    ctx.warped_gradient(&p);
    let mut jac = vec![0f32; ctx.len() * 8];
    let (gx, gy) = ctx.work().gradients();
    g.bench_function("project", |b| {
        b.iter(|| {
            regtrack::sm::newton::project(gx, gy, ctx.problem().dwdp0().0, 8, black_box(&mut jac))
        })
    });
    // The compositional methods' projection: the homography's closed form at the identity.
    g.bench_function("project, closed form", |b| {
        b.iter(|| {
            let (grid_x, grid_y) = ctx.problem().grid();
            ctx.ssm()
                .project_at_identity(gx, gy, grid_x, grid_y, black_box(&mut jac))
        })
    });
    let mut h = [0.0; regtrack::linalg::MAX_DOF * regtrack::linalg::MAX_DOF];
    let values = ctx.values().to_vec();
    g.bench_function("J^T J", |b| {
        b.iter(|| {
            ctx.problem_mut().am_mut().hessian(
                regtrack::am::Wrt::Current,
                regtrack::am::HessianKind::GaussNewton,
                &values,
                black_box(&jac),
                8,
                &mut h,
            )
        })
    });
    // MI's Newton Hessian (FCLK and ESM, every iteration) on the same patch and Jacobian: the
    // histogram's statistics are those of the last call, so this is the projection alone.
    let spec = TrackerSpec::from_names("fclk", "mi", "homography").expect("spec");
    let mut t =
        RegistrationTracker::new(spec.registration().expect("registration")).expect("tracker");
    t.initialize(FrameInput::Smoothed(&smoothed), &truth)
        .expect("init");
    t.set_corners(&start).expect("corners");
    let mut mi = t.into_context();
    let q = mi.params();
    mi.sample_at(&view, &q);
    let mi_values = mi.values().to_vec();
    g.bench_function("MI Newton Hessian", |b| {
        b.iter(|| {
            mi.problem_mut().am_mut().hessian(
                regtrack::am::Wrt::Current,
                regtrack::am::HessianKind::Newton,
                &mi_values,
                black_box(&jac),
                8,
                &mut h,
            )
        })
    });
    let mut jg = [0.0; regtrack::linalg::MAX_DOF];
    g.bench_function("J^T g", |b| {
        b.iter(|| regtrack::linalg::jt_times(black_box(&jac), ctx.work().grad(), 8, &mut jg))
    });
    // What the forward SSD methods run instead of the projection, `J^T J` and `J^T g`: the
    // Newton system from the gradient's moments on the grid.
    {
        let (ga, gb) = ctx.work().gradients();
        let (ga, gb, grad) = (ga.to_vec(), gb.to_vec(), ctx.work().grad().to_vec());
        let moments = ctx
            .problem_mut()
            .moments_mut()
            .expect("SSD on the homography has the moments");
        g.bench_function("J^T J and J^T g from the moments", |b| {
            b.iter(|| moments.minus_jtj_and_jtr(black_box(&ga), &gb, &grad, &mut h, &mut jg))
        });
    }
    // The loss checks' confidence (4 x 4 blocks of the 50 x 50 patch), twice a frame at least.
    let (t0, t1): (Vec<f32>, Vec<f32>) = (
        smoothed.data[..2500].to_vec(),
        smoothed.data[2500..5000].to_vec(),
    );
    let confidence = regtrack::registration::BlockCorrelation::new(&t0, 50, 4);
    g.bench_function("confidence", |b| b.iter(|| confidence.of(black_box(&t1))));
    g.finish();

    let mut pre = Preprocessor::new(gaussian_kernel(5, 3.0));
    c.bench_function("preprocess 150x150 region (5x5 Gaussian)", |b| {
        b.iter(|| {
            pre.process(
                black_box(&img),
                regtrack::geometry::Rect::new(225.0, 125.0, 375.0, 275.0),
            )
        })
    });
    // The coarse pyramid levels the gradient methods search first (two by default).
    c.bench_function("pyramid levels 1-2 of a 150x150 region", |b| {
        b.iter(|| pre.build_levels(black_box(2)))
    });

    // Nearest-neighbour search: index build (initialisation) and one query-and-step.
    for sm in ["nn1k", "nn10k"] {
        let spec = TrackerSpec::from_names(sm, "ssd", "homography").expect("spec");
        let mut t = Tracker::new(&spec).expect("tracker");
        c.bench_function(&format!("{sm} index build"), |b| {
            b.iter(|| {
                t.initialize(FrameInput::Smoothed(&smoothed), &truth)
                    .expect("init")
            })
        });
        one_iteration(c, &spec);
    }

    // The particle filter at 1,000 particles: a whole frame (5 rounds), from the same start each
    // time, on one thread and on every core.
    for ssm in ["translation", "homography"] {
        for threads in ["1", "0"] {
            let mut spec = TrackerSpec::from_names("pf", "ssd", ssm).expect("spec");
            spec.set_param("threads", threads).expect("param");
            let mut t = Tracker::new(&spec).expect("tracker");
            t.initialize(FrameInput::Smoothed(&smoothed), &truth)
                .expect("init");
            let on = if threads == "1" {
                "one thread"
            } else {
                "every core"
            };
            c.bench_function(&format!("pf_ssd_{ssm} frame, {on}"), |b| {
                b.iter(|| {
                    t.set_corners(&start).expect("corners");
                    black_box(t.update(FrameInput::Smoothed(&smoothed), &mut NoObserver))
                })
            });
        }
    }
}

/// The many-patch tracker: a frame of 500 patches (21 x 21, 3 levels, one thread; translation
/// also on every core) moving by
/// about a pixel and a half, back and forth between two frames of a real texture.
fn patches(c: &mut Criterion) {
    use regtrack::imaging::{GrayU8, sample_value};
    use regtrack::patches::{PatchParams, PatchTracker};
    let img = load_gray(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("assets/textures/skimage_coffee.png"),
    )
    .expect("bundled texture");
    let f = img.to_f32();
    let view = f.view();
    let mut moved = GrayU8::new(img.width, img.height);
    for y in 0..img.height {
        for x in 0..img.width {
            let v = sample_value(&view, x as f32 + 1.3, y as f32 - 0.7);
            moved.set(x, y, v.round().clamp(0.0, 255.0) as u8);
        }
    }
    let mut g = c.benchmark_group("patches");
    for (warp, threads) in [("translation", 1), ("affine", 1), ("translation", 0)] {
        let params = PatchParams::parse(&[
            ("warp".into(), warp.into()),
            ("size".into(), "21".into()),
            ("levels".into(), "3".into()),
            ("threads".into(), threads.to_string()),
            ("min_distance".into(), "4".into()),
        ])
        .expect("params");
        let on = if threads == 1 { "" } else { ", every core" };
        let mut t = PatchTracker::new(params).expect("tracker");
        let points = t.detect(&img, 500, None);
        t.initialize(&img, &points).expect("init");
        let frames = [&moved, &img];
        let mut k = 0;
        g.bench_function(format!("{warp} frame, {} patches{on}", points.len()), |b| {
            b.iter(|| {
                t.update(frames[k % 2]).expect("update");
                k += 1;
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench, patches);
criterion_main!(benches);
