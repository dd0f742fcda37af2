//! The hot path does not allocate: once a tracker is initialised, `update` on 8-bit frames
//! (pre-processing included) makes no heap allocation. Counted per thread by the test binary's
//! global allocator.

use crate::common::{colour_texture, full_tests, texture};
use regtrack::geometry::Quad;
use regtrack::observe::NoObserver;
use regtrack::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

/// Counts the allocations of the current thread.
pub struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded unchanged to the system allocator.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

fn allocations() -> usize {
    ALLOCATIONS.with(|c| c.get())
}

#[test]
fn update_does_not_allocate() {
    // The counter sees allocations.
    let before = allocations();
    let v = std::hint::black_box(vec![1u8; 100]);
    assert!(allocations() > before && v.len() == 100);
    let img = texture("skimage_coffee.png");
    let colour = colour_texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let shifted: Vec<Quad> = (0..6)
        .map(|k| {
            truth
                .map(|p| regtrack::geometry::Point::new(p.x + 0.7 * k as f64, p.y - 0.4 * k as f64))
        })
        .collect();
    // Every SM x AM of the registries; by default each on one of the SSMs in turn (every SSM
    // is met across the grid), with REGTRACK_FULL_TESTS=1 on each of them. A combination that
    // does not build must be one the capabilities refuse. Two threads share the combinations:
    // the counter is per thread, so each sees only its own tracker's allocations.
    let ssms = regtrack::ssm::REGISTRY;
    let (method, tracker) = (
        regtrack::params::MethodParams::default(),
        regtrack::tracker::TrackerParams::default(),
    );
    let cfg = regtrack::sm::SmConfig {
        method: &method,
        tracker: &tracker,
    };
    let mut combos = Vec::new();
    let mut pair = 0;
    for sm in regtrack::sm::REGISTRY {
        let method = regtrack::sm::build(sm.name, &cfg).unwrap();
        for am in regtrack::am::REGISTRY {
            let model = am.build.default_model();
            let allowed = |ssm: &str| {
                regtrack::tracker::allowed(&*method, &*model, &*regtrack::ssm::build(ssm).unwrap())
            };
            pair += 1;
            // By default the pair's SSM in turn, or the next one the capabilities allow.
            let turn = (0..ssms.len())
                .map(|i| (pair + i) % ssms.len())
                .find(|&k| allowed(ssms[k].name))
                .unwrap_or(pair % ssms.len());
            for (k, ssm) in ssms.iter().enumerate() {
                if !(full_tests() || turn == k) {
                    continue;
                }
                let refused = !allowed(ssm.name);
                match TrackerSpec::from_names(sm.name, am.name, ssm.name) {
                    Ok(spec) => {
                        assert!(!refused, "{} x {} builds", sm.name, am.name);
                        combos.push(spec);
                    }
                    Err(e) => assert!(
                        refused,
                        "{} x {} x {} does not build: {e}",
                        sm.name, am.name, ssm.name
                    ),
                }
            }
        }
    }
    // Every SSM met, and most pairs run.
    let met: std::collections::BTreeSet<String> = combos
        .iter()
        .filter_map(|s| s.registration().map(|r| r.ssm.clone()))
        .collect();
    assert_eq!(met.len(), ssms.len(), "{met:?}");
    assert!(combos.len() * 10 >= pair * 8, "{} of {pair}", combos.len());
    // Selective pixel integration (the searches read part of the grid, the confidences the
    // whole grid), on the affine warp: with a pyramid below.
    for sm in regtrack::sm::REGISTRY {
        for am in ["ssd", "pca"] {
            if let Ok(mut spec) = TrackerSpec::from_names(sm.name, am, "affine") {
                spec.set_param("spi", "gradient").unwrap();
                spec.set_param("spi_mask_right", "0.2").unwrap();
                spec.set_param("spi_mask_bottom", "1").unwrap();
                combos.push(spec);
            }
        }
    }
    // Colour (`channels = rgb`, each AM channel by channel) with every AM, on the homography
    // (the search methods in turn, the next that takes the AM).
    let sms = regtrack::sm::REGISTRY;
    for (k, am) in regtrack::am::REGISTRY.iter().enumerate() {
        let mut spec = (0..sms.len())
            .find_map(|i| {
                TrackerSpec::from_names(sms[(k + i) % sms.len()].name, am.name, "homography").ok()
            })
            .unwrap_or_else(|| panic!("no search method takes {}", am.name));
        spec.set_param("channels", "rgb").unwrap();
        combos.push(spec.clone());
        // And on the descriptor fields (`channels = df`, the AM stacked on the four; not the
        // models of grey-level histograms, which refuse them).
        spec.set_param("channels", "df").unwrap();
        if !matches!(am.name, "mi" | "ccre") {
            combos.push(spec);
        }
    }
    let check = |mut spec: TrackerSpec| {
        // A pyramid too (its levels are kept between frames as well).
        let affine = spec.registration().is_some_and(|r| r.ssm == "affine");
        spec.params_mut().unwrap().pyramid_levels = if affine { 3 } else { 1 };
        let mut t = Tracker::new(&spec).unwrap();
        let input = if t.channels() == 3 {
            FrameInput::Colour(&colour)
        } else {
            FrameInput::Gray8(&img)
        };
        t.initialize(input, &truth).unwrap();
        // A first update grows the buffers of the pre-processed region.
        t.set_corners(&shifted[5]).unwrap();
        t.update(input, &mut NoObserver);
        let before = allocations();
        for q in &shifted {
            t.set_corners(q).unwrap();
            let out = t.update(input, &mut NoObserver);
            assert_eq!(out.status, TrackStatus::Tracking, "{}", spec.label());
        }
        assert_eq!(
            allocations() - before,
            0,
            "{} allocates in update",
            spec.label()
        );
    };
    let (even, odd): (Vec<_>, Vec<_>) = combos
        .into_iter()
        .enumerate()
        .partition(|(i, _)| i % 2 == 0);
    std::thread::scope(|s| {
        for half in [even, odd] {
            s.spawn(|| half.into_iter().for_each(|(_, spec)| check(spec)));
        }
    });
}

/// The many-patch tracker's update (one thread) does not allocate once its buffers have the
/// frame's size: not for the frame's levels, not per patch.
#[test]
fn a_patch_update_does_not_allocate() {
    use regtrack::patches::{PatchParams, PatchTracker};
    let img = crate::common::texture("skimage_coffee.png");
    let mut moved = img.clone();
    for y in 0..img.height {
        for x in 0..img.width {
            moved.set(x, y, img.get((x + 1).min(img.width - 1), y));
        }
    }
    for warp in ["translation", "affine"] {
        let prm = PatchParams::parse(&[
            ("warp".into(), warp.into()),
            ("threads".into(), "1".into()),
            ("fb_max".into(), "1".into()),
        ])
        .unwrap();
        let mut t = PatchTracker::new(prm).unwrap();
        let pts = t.detect(&img, 100, None);
        t.initialize(&img, &pts).unwrap();
        t.update(&moved).unwrap();
        let before = allocations();
        t.update(&img).unwrap();
        t.update(&moved).unwrap();
        assert_eq!(allocations() - before, 0, "{warp}");
        assert!(t.tracking() > 50, "{warp}: {}", t.tracking());
    }
}
