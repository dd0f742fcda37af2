//! Generic recovery tests: every AM x SSM x SM from the registries recovers a known warp on a real
//! texture (the Baker-Matthews protocol).

use crate::common::texture;
use rayon::prelude::*;
use regtrack::geometry::{Quad, alignment_error};
use regtrack::observe::NoObserver;
use regtrack::rng::Rng;
use regtrack::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};
use regtrack::{am, sm, ssm};

/// Runs `trials` perturbations of sigma `sigma` px (projected onto the SSM) of a 100x100
/// template; returns how many ended within `tol` px of the truth.
fn converged(spec: &TrackerSpec, sigma: f64, trials: usize, tol: f64, seed: u64) -> usize {
    let img = texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let mut tracker = Tracker::new(spec).unwrap();
    tracker.initialize(FrameInput::Gray8(&img), &truth).unwrap();
    let model = ssm::build(&spec.ssm).unwrap();
    let mut rng = Rng::new(seed);
    let mut ok = 0;
    for _ in 0..trials {
        let p = ssm::random_warp(&*model, &truth, sigma, &mut rng).unwrap();
        let start = ssm::warp_quad(&*model, &p, &truth);
        tracker.set_corners(&start).unwrap();
        let out = tracker.update(FrameInput::Gray8(&img), &mut NoObserver);
        assert!(out.corners.is_finite());
        if out.status == TrackStatus::Tracking && alignment_error(&out.corners, &truth) < tol {
            ok += 1;
        }
    }
    ok
}

#[test]
fn every_combination_recovers_a_known_warp() {
    let mut combos = Vec::new();
    for s in sm::REGISTRY {
        for a in am::REGISTRY {
            for m in ssm::REGISTRY {
                combos.push(TrackerSpec::from_names(s.name, a.name, m.name).unwrap());
            }
        }
    }
    let results: Vec<(String, usize)> = combos
        .par_iter()
        .map(|spec| (spec.label(), converged(spec, 2.0, 100, 0.1, 42)))
        .collect();
    for (label, ok) in &results {
        eprintln!("{label}: {ok}/100");
    }
    let failures: Vec<_> = results.iter().filter(|(_, ok)| *ok < 95).collect();
    assert!(
        failures.is_empty(),
        "combinations converging in fewer than 95 of 100 trials: {failures:?}"
    );
}

#[test]
fn baker_matthews_homography_ssd_sigma_4() {
    for sm in ["iclk", "fclk", "esm"] {
        let mut spec = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        spec.params.max_iters = 15;
        let ok = converged(&spec, 4.0, 100, 1.0, 7);
        eprintln!("Baker-Matthews sigma 4: {sm}: {ok}/100");
        assert!(ok >= 95, "{sm}: {ok}/100 converged at sigma 4 px");
        // The frequency of convergence falls with larger perturbations (the test can fail).
        let far = converged(&spec, 12.0, 100, 1.0, 7);
        eprintln!("Baker-Matthews sigma 12: {sm}: {far}/100");
        assert!(far < ok, "{sm}: {far}/100 at sigma 12 px, {ok}/100 at 4 px");
    }
}

#[test]
fn a_pyramid_widens_the_basin_of_convergence() {
    for sm in ["esm", "iclk", "fclk"] {
        let one = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        let mut three = one.clone();
        three.params.pyramid_levels = 3;
        let (a, b) = (
            converged(&one, 10.0, 60, 0.1, 3),
            converged(&three, 10.0, 60, 0.1, 3),
        );
        eprintln!("sigma 10 px: {sm} 1 level {a}/60, 3 levels {b}/60");
        assert!(b > a, "{sm}: 3 levels {b}/60 vs 1 level {a}/60");
    }
    // And it still recovers small perturbations exactly, in every SSM.
    for m in ssm::REGISTRY {
        let mut spec = TrackerSpec::from_names("esm", "zncc", m.name).unwrap();
        spec.params.pyramid_levels = 2;
        let ok = converged(&spec, 2.0, 50, 0.1, 5);
        assert!(ok >= 48, "{}: {ok}/50 with a 2-level pyramid", m.name);
    }
}
