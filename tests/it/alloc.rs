//! The hot path does not allocate: once a tracker is initialised, `update` on 8-bit frames
//! (pre-processing included) makes no heap allocation. Counted per thread by the test binary's
//! global allocator.

use crate::common::texture;
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
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let shifted: Vec<Quad> = (0..6)
        .map(|k| {
            truth
                .map(|p| regtrack::geometry::Point::new(p.x + 0.7 * k as f64, p.y - 0.4 * k as f64))
        })
        .collect();
    for sm in regtrack::sm::REGISTRY {
        for am in regtrack::am::REGISTRY {
            for ssm in ["homography", "sl3", "corner", "affine"] {
                let mut spec = match TrackerSpec::from_names(sm.name, am.name, ssm) {
                    Ok(spec) => spec,
                    // Combinations the capabilities refuse (NN with MI, a gradient SM with SAD)
                    // are not trackers; the recovery test checks that they say why.
                    Err(regtrack::Error::Incompatible(_)) => continue,
                    Err(e) => panic!("{e}"),
                };
                // A pyramid too (its levels are kept between frames as well).
                spec.params_mut().unwrap().pyramid_levels = if ssm == "affine" { 3 } else { 1 };
                let mut t = Tracker::new(&spec).unwrap();
                t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
                // A first update grows the buffers of the pre-processed region.
                t.set_corners(&shifted[5]).unwrap();
                t.update(FrameInput::Gray8(&img), &mut NoObserver);
                let before = allocations();
                for q in &shifted {
                    t.set_corners(q).unwrap();
                    let out = t.update(FrameInput::Gray8(&img), &mut NoObserver);
                    assert_eq!(out.status, TrackStatus::Tracking);
                }
                assert_eq!(
                    allocations() - before,
                    0,
                    "{} allocates in update",
                    spec.label()
                );
            }
        }
    }
}
