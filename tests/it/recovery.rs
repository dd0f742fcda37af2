//! Generic recovery tests: every AM x SSM x SM from the registries recovers a known warp on a real
//! texture (the Baker-Matthews protocol).

use crate::common::{colour_texture, full_tests, paper_settings, texture};
use rayon::prelude::*;
use regtrack::geometry::{Quad, alignment_error};
use regtrack::observe::NoObserver;
use regtrack::params::MethodParams;
use regtrack::rng::Rng;
use regtrack::spec::TrackerParams;
use regtrack::tracker::{FrameInput, TrackStatus, Tracker, TrackerSpec};
use regtrack::{am, sm, ssm};

/// Runs `trials` perturbations of sigma `sigma` px (projected onto the SSM) of a 100x100
/// template; returns how many ended within `tol` px of the truth.
fn converged(spec: &TrackerSpec, sigma: f64, trials: usize, tol: f64, seed: u64) -> usize {
    recovered(spec, sigma, trials, tol, seed, false).0
}

/// Like [`converged`], but with `own_optimum` the trials must end within `tol` px of where the
/// tracker converges when started at the truth (its own optimum) instead of the truth. Also
/// returns the distance of that optimum from the truth.
fn recovered(
    spec: &TrackerSpec,
    sigma: f64,
    trials: usize,
    tol: f64,
    seed: u64,
    own_optimum: bool,
) -> (usize, f64) {
    // A colour tracker (`channels = rgb`) is given the texture in colour.
    let (grey, colour) = (
        texture("skimage_coffee.png"),
        colour_texture("skimage_coffee.png"),
    );
    let mut tracker = Tracker::new(spec).unwrap();
    let input = if tracker.channels() == 3 {
        FrameInput::Colour(&colour)
    } else {
        FrameInput::Gray8(&grey)
    };
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    tracker.initialize(input, &truth).unwrap();
    let optimum = tracker.update(input, &mut NoObserver).corners;
    let goal = if own_optimum { optimum } else { truth };
    // The start: the truth moved by a random warp of the SSM; for a non-rigid SSM (laid on
    // the tracker's own normalised quad) the truth's corners moved at random (the
    // homography's random warp), which the tracker fits.
    let model = ssm::build(&spec.registration().unwrap().ssm).unwrap();
    let model = if model.projective() {
        model
    } else {
        ssm::build("homography").unwrap()
    };
    let mut rng = Rng::new(seed);
    let mut ok = 0;
    for _ in 0..trials {
        let p = ssm::random_warp(&*model, &truth, sigma, &mut rng).unwrap();
        let start = ssm::warp_quad(&*model, &p, &truth);
        tracker.set_corners(&start).unwrap();
        let out = tracker.update(input, &mut NoObserver);
        assert!(out.corners.is_finite());
        if out.status == TrackStatus::Tracking && alignment_error(&out.corners, &goal) < tol {
            ok += 1;
        }
    }
    (ok, alignment_error(&optimum, &truth))
}

/// How far (px) the optimum of an AM may be from the truth, for the AMs whose optimum is not at
/// `I = I*` (`None`: it is, and the trials must recover the truth itself).
///
/// The Parzen-window estimates of MI and CCRE (cubic B-spline) are biased: their gradient with
/// respect to the pixels does not vanish at `I = I*` (the window rewards spreading the
/// intensities), so on this texture each SM's fixed point started from the truth is off. The bias
/// falls with more bins: under the 8-DOF warps MI is off by 1.16-1.25 px with the paper's 8 bins,
/// 0.27-0.30 px with 16 (the default) and 0.10 px with 32; CCRE by 0.69-0.75, 0.11 and 0.17 px;
/// under 2-4 DOF by 0.04-0.07 px at 16 bins (measured). For these the test is that every
/// SM x SSM converges to its own optimum (within 0.1 px, >= 95 of 100 perturbations: the basin)
/// and that this optimum is within the bound below of the truth. The sampling methods end where
/// their samples are (PF-MI 1.0 px off on the homography), so their bound is looser.
///
/// ICLK with CCRE is the exception: CCRE is not symmetric (only the template side is cumulated),
/// so ICLK's template-side linearisation optimises a different criterion whose fixed point drifts
/// away under warps with more than 3 DOF (0.22 px similitude, 0.8 px affine, 7.5 px for the 8-DOF
/// warps after 30 iterations at 16 bins, measured); only its 2-3 DOF optimum is bounded here,
/// which matches the paper's finding that CCRE does poorly with gradient-based SMs. NNIC ends
/// with ICLK, so the same holds for it.
fn optimum_bias(sm: &str, am: &str, ssm: &str) -> Option<f64> {
    let sampled = sampling(sm);
    let sm = if sm == "nnic" { "iclk" } else { sm };
    match (sm, am) {
        (_, "mi" | "ccre") if sampled => Some(1.5),
        (_, "mi") => Some(0.5),
        ("iclk", "ccre") if ssm == "translation" || ssm == "isometry" => Some(0.5),
        ("iclk", "ccre") => Some(f64::INFINITY),
        (_, "ccre") => Some(0.25),
        _ => None,
    }
}

/// Whether a search method searches by sampling (no derivatives): its precision is that of its
/// samples, not of a Newton step.
fn sampling(sm_name: &str) -> bool {
    !search_method(sm_name).requires().derivatives
}

/// The search method `name` with the default parameters.
fn search_method(name: &str) -> Box<dyn sm::SearchMethod> {
    let (method, tracker) = (MethodParams::default(), TrackerParams::default());
    let cfg = sm::SmConfig {
        method: &method,
        tracker: &tracker,
    };
    sm::build(name, &cfg).unwrap()
}

#[test]
fn every_combination_recovers_a_known_warp() {
    // Every AM x SSM x SM that the capabilities allow is built and run; the others must be
    // refused with the reason.
    // REGTRACK_RECOVERY_AM=name runs one model's combinations only (when working on it).
    let only = std::env::var("REGTRACK_RECOVERY_AM").ok();
    let mut combos = Vec::new();
    for s in sm::REGISTRY {
        for a in am::REGISTRY
            .iter()
            .filter(|a| only.as_deref().is_none_or(|o| o == a.name))
        {
            for m in ssm::REGISTRY {
                match TrackerSpec::from_names(s.name, a.name, m.name) {
                    Ok(spec) => combos.push((spec, sampling(s.name))),
                    Err(e) => {
                        // Refused only where the capabilities say so, and with the reason.
                        let msg = e.to_string();
                        let allowed = regtrack::tracker::allowed(
                            &*search_method(s.name),
                            &*a.build.default_model(),
                            &*ssm::build(m.name).unwrap(),
                        );
                        assert!(
                            !allowed
                                && msg.contains("incompatible")
                                && (msg.contains(a.name) || msg.contains(s.name)),
                            "{} x {} x {} refused without a reason: {msg}",
                            s.name,
                            a.name,
                            m.name
                        );
                    }
                }
            }
        }
    }
    // Gradient methods: 100 trials within 0.1 px. Sampling methods (NN, PF) are as precise as
    // their samples: 40 trials within 3 px (the start is about 2.5 px off), and a separate test
    // below holds them to 0.5 px on translation. MI and CCRE are held to their own optimum (see
    // `optimum_bias`). By default the first 20 and 10 of those trials (the same seeded warps; 5
    // for the particle filter, below); REGTRACK_FULL_TESTS=1 runs them all.
    let (gradient_trials, sampling_trials) = if full_tests() { (100, 40) } else { (20, 10) };
    let results: Vec<(String, usize, usize, f64, Option<f64>)> = combos
        .par_iter()
        .map(|(spec, sampled)| {
            let r = spec.registration().unwrap();
            let (trials, tol) = if *sampled {
                (sampling_trials, 3.0)
            } else {
                (gradient_trials, 0.1)
            };
            // The non-rigid SSMs (18 and 50 parameters, each iteration the dearer) on fewer
            // trials by default: half, a quarter for 50.
            let dof = ssm::build(&r.ssm).unwrap().dof();
            let trials = match dof {
                _ if full_tests() => trials,
                0..=8 => trials,
                9..=18 => trials / 2,
                _ => trials / 4,
            };
            // The particle filter weighs 5 rounds of 1000 particles at every update, so its 144
            // combinations were half of this test's time: by default 5 of its seeded trials.
            let trials = if r.sm == "pf" && !full_tests() {
                trials / 2
            } else {
                trials
            };
            let bound = optimum_bias(&r.sm, &r.am, &r.ssm);
            let (ok, bias) = recovered(spec, 2.0, trials, tol, 42, bound.is_some());
            (spec.label(), ok, trials, bias, bound)
        })
        .collect();
    for (label, ok, n, bias, bound) in &results {
        match bound {
            Some(_) => {
                eprintln!("{label}: {ok}/{n} to its own optimum, {bias:.3} px from the truth")
            }
            None => eprintln!("{label}: {ok}/{n}"),
        }
    }
    let failures: Vec<_> = results
        .iter()
        .filter(|(_, ok, n, bias, bound)| {
            // At most 5% of the trials may miss (rounded down: 1 of 20, none of 10).
            n - ok > n / 20 || bound.is_some_and(|b| *bias > b)
        })
        .collect();
    assert!(
        failures.is_empty(),
        "combinations converging in fewer than 95% of the trials, or to an optimum too far from \
         the truth: {failures:?}"
    );
}

#[test]
fn sampling_methods_are_precise_on_low_dof_and_seeded() {
    // Every method of the registry that searches elsewhere than at its parameters (NN, PF,
    // NNIC, the grid methods: not `local`), to half a pixel on the low-DOF warps.
    let nonlocal: Vec<&str> = sm::REGISTRY
        .iter()
        .filter(|e| !search_method(e.name).local())
        .map(|e| e.name)
        .collect();
    for name in ["nn1k", "pf", "nnic", "grid", "rklt"] {
        assert!(nonlocal.contains(&name), "{nonlocal:?}");
    }
    for sm in nonlocal {
        for m in ["translation", "similitude"] {
            let spec = TrackerSpec::from_names(sm, "ssd", m).unwrap();
            let ok = converged(&spec, 2.0, 40, 0.5, 7);
            assert!(ok >= 38, "{sm} {m}: {ok}/40 within 0.5 px");
        }
    }
    // The same seed gives the same result, on any number of threads; another seed another one.
    let run_on = |seed: u64, threads: f64| {
        let mut spec = TrackerSpec::from_names("pf", "ssd", "homography").unwrap();
        spec.params_mut().unwrap().seed = seed;
        spec.registration_mut()
            .unwrap()
            .method
            .set("threads", threads);
        let img = texture("skimage_coffee.png");
        let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
        let start = Quad::from_rect(252.0, 149.0, 100.0, 100.0);
        t.set_corners(&start).unwrap();
        t.update(FrameInput::Gray8(&img), &mut NoObserver).corners
    };
    let run = |seed: u64| run_on(seed, 1.0);
    assert_eq!(run(3), run(3));
    assert_eq!(run(3), run_on(3, 2.0));
    assert_eq!(run(3), run_on(3, 3.0));
    assert_ne!(run(3), run(4));
    // What the inspector draws: each round's particles (before resampling) and their weights.
    let spec = TrackerSpec::from_names("pf", "ssd", "homography").unwrap();
    let img = texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let mut t = Tracker::new(&spec).unwrap();
    t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
    t.set_corners(&Quad::from_rect(252.0, 149.0, 100.0, 100.0))
        .unwrap();
    let mut seen = regtrack::observe::Recorder {
        visuals: true,
        ..Default::default()
    };
    t.update(FrameInput::Gray8(&img), &mut seen);
    assert!(!seen.method_visuals.is_empty());
    for v in &seen.method_visuals {
        assert_eq!(
            (v.quads.len(), v.weights.len()),
            (1000, 1000),
            "{}",
            v.label
        );
        let top = v.weights.iter().copied().fold(0.0, f32::max);
        assert!(top == 1.0 && v.weights.iter().all(|w| (0.0..=1.0).contains(w)));
        // Particles spread around the target, a few pixels at most.
        let mean_error = v
            .quads
            .iter()
            .map(|q| alignment_error(q, &truth))
            .sum::<f64>()
            / 1000.0;
        assert!(
            mean_error < 8.0,
            "particles {mean_error} px from the target"
        );
    }
}

#[test]
fn nnic_is_at_least_as_precise_as_nn_and_iclk_alone_on_large_motion() {
    // At sigma 6 px ICLK alone often fails; NN brings it into ICLK's basin.
    let at = |sm: &str, tol: f64| {
        let spec = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        converged(&spec, 6.0, 60, tol, 11)
    };
    let (nnic, iclk, nn) = (at("nnic", 0.1), at("iclk", 0.1), at("nn1k", 0.1));
    eprintln!("sigma 6 px, within 0.1 px: nnic {nnic}, iclk {iclk}, nn1k {nn} of 60");
    assert!(
        nnic >= iclk && nnic >= nn,
        "nnic {nnic} iclk {iclk} nn {nn}"
    );
}

#[test]
fn baker_matthews_homography_ssd_sigma_4() {
    for sm in ["iclk", "fclk", "esm"] {
        let mut spec = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        spec.params_mut().unwrap().max_iters = 15;
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
        let mut one = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        one.params_mut().unwrap().pyramid_levels = 1;
        let mut three = one.clone();
        three.params_mut().unwrap().pyramid_levels = 3;
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
        spec.params_mut().unwrap().pyramid_levels = 2;
        let ok = converged(&spec, 2.0, 50, 0.1, 5);
        eprintln!("{}: {ok}/50 with a 2-level pyramid", m.name);
        assert!(ok >= 48, "{}: {ok}/50 with a 2-level pyramid", m.name);
    }
}

#[test]
fn the_projected_nn_index_is_as_accurate_as_exact_search() {
    // The default index ranks by a sparse random projection and re-ranks a few candidates
    // exactly; it must find warps as good as brute force does.
    for m in ["similitude", "homography"] {
        let mut exact = TrackerSpec::from_names("nn1k", "ssd", m).unwrap();
        exact.set_param("index", "exact").unwrap();
        let projected = TrackerSpec::from_names("nn1k", "ssd", m).unwrap();
        let (e, p) = (
            converged(&exact, 2.0, 60, 1.0, 5),
            converged(&projected, 2.0, 60, 1.0, 5),
        );
        eprintln!("nn1k {m} within 1 px: exact {e}/60, projected {p}/60");
        assert!(p + 3 >= e, "{m}: projected {p} vs exact {e}");
        assert!(e >= 45, "{m}: exact {e}");
    }
    // MI has no embedding: the projected index pre-ranks by normalised intensities and re-ranks
    // by MI; exact search scores every sample by MI.
    let mut exact = TrackerSpec::from_names("nn1k", "mi", "similitude").unwrap();
    exact.set_param("index", "exact").unwrap();
    let projected = TrackerSpec::from_names("nn1k", "mi", "similitude").unwrap();
    let (e, p) = (
        converged(&exact, 2.0, 30, 1.0, 5),
        converged(&projected, 2.0, 30, 1.0, 5),
    );
    eprintln!("nn1k mi similitude within 1 px: exact {e}/30, projected {p}/30");
    assert!(p + 2 >= e && e >= 22, "projected {p} vs exact {e}");
}

#[test]
fn composites_recover_known_warps() {
    // Levenberg-Marquardt variants, a cascade and a parallel combination, as the registry's
    // methods are tested above.
    for sm in [
        "lm:iclk",
        "lm:fclk",
        "lm:esm",
        "lm:falk",
        "cascade:nn1k+esm",
        "parallel:esm+fclk",
    ] {
        let spec = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        let ok = converged(&spec, 2.0, 50, 0.1, 42);
        eprintln!("{sm}: {ok}/50");
        assert!(ok >= 48, "{sm}: {ok}/50");
    }
    // Damping trades speed for a wider basin: at sigma 8 px it does not do worse.
    for sm in ["iclk", "esm"] {
        let plain = TrackerSpec::from_names(sm, "ssd", "homography").unwrap();
        let lm = TrackerSpec::from_names(&format!("lm:{sm}"), "ssd", "homography").unwrap();
        let (p, l) = (
            converged(&plain, 8.0, 60, 0.1, 3),
            converged(&lm, 8.0, 60, 0.1, 3),
        );
        eprintln!("sigma 8 px: {sm} {p}/60, lm:{sm} {l}/60");
        assert!(l + 3 >= p, "lm:{sm} {l} vs {sm} {p}");
    }
}

#[test]
fn the_ssm_hierarchy_recovers_known_warps() {
    // MTF's hrch: translation, similitude and affine first, then the tracker's SSM.
    for (sm, m) in [
        ("iclk", "homography"),
        ("esm", "homography"),
        ("fclk", "affine"),
    ] {
        let mut h = TrackerSpec::from_names(sm, "zncc", m).unwrap();
        h.set_param("ssm_hierarchy", "on").unwrap();
        let ok = converged(&h, 2.0, 50, 0.1, 42);
        let plain = TrackerSpec::from_names(sm, "zncc", m).unwrap();
        let (p8, h8) = (
            converged(&plain, 8.0, 60, 0.1, 3),
            converged(&h, 8.0, 60, 0.1, 3),
        );
        eprintln!("{sm} {m} hierarchy: {ok}/50 at 2 px; at 8 px {h8}/60 (plain {p8}/60)");
        assert!(ok >= 48, "{sm} {m}: {ok}/50");
        assert!(h8 + 6 >= p8, "{sm} {m}: {h8} vs {p8}");
    }
}

#[test]
fn more_bins_make_the_histogram_models_less_biased() {
    // The `bins` parameter reaches MI and CCRE: with 32 bins instead of the paper's 8 their
    // optimum (where the tracker started at the truth converges) is much nearer the truth, and the
    // trials still converge to it.
    let mut report = Vec::new();
    for am in ["mi", "ccre"] {
        let mut bias = Vec::new();
        for bins in ["8", "32"] {
            // The paper's tracker: the bias is the AM's, which the robust defaults' checks and
            // polish (by the confidence) partly hide.
            let mut spec = TrackerSpec::from_names("esm", am, "homography").unwrap();
            paper_settings(&mut spec);
            spec.set_param("bins", bins).unwrap();
            let (ok, b) = recovered(&spec, 2.0, 20, 0.1, 3, true);
            report.push(format!(
                "{am} bins={bins}: {ok}/20 to its optimum, {b:.3} px off"
            ));
            assert!(ok >= 18, "{report:#?}");
            bias.push(b);
        }
        assert!(bias[1] < 0.5 * bias[0], "{report:#?}");
    }
    eprintln!("{report:#?}");
}

#[test]
fn every_stage_of_a_pyramid_and_of_the_ssm_hierarchy_has_the_am_parameters() {
    // The coarse levels and the hierarchy's stages once built their AM with default parameters,
    // so `bins` reached only the finest level's search. Each stage's first similarity on the same
    // frame, from the same start, depends on its AM's bins: with bins=8 every stage must differ
    // from the default (16) and match a tracker whose bins are set to 8 the same way.
    use regtrack::observe::Recorder;
    let img = texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let start = truth.map(|p| regtrack::Point::new(p.x + 1.5, p.y - 1.0));
    // (level, iteration) -> similarity of each stage's first iteration on the frame.
    let first_similarities = |setup: &[(&str, &str)]| {
        let mut spec = TrackerSpec::from_names("esm", "mi", "homography").unwrap();
        for (k, v) in setup {
            spec.set_param(k, v).unwrap();
        }
        let mut tracker = Tracker::new(&spec).unwrap();
        tracker.initialize(FrameInput::Gray8(&img), &truth).unwrap();
        tracker.set_corners(&start).unwrap();
        let mut rec = Recorder::default();
        tracker.update(FrameInput::Gray8(&img), &mut rec);
        // The first iteration of each stage: where the level changes, or the hierarchy's stages
        // (level 0) start, which the parameter count tells apart.
        let mut firsts: Vec<(usize, usize, f64)> = Vec::new();
        for r in &rec.iterations {
            if firsts
                .last()
                .is_none_or(|&(l, n, _)| l != r.level || n != r.params.len())
            {
                firsts.push((r.level, r.params.len(), r.similarity));
            }
        }
        firsts
    };
    for setup in [vec![("pyramid_levels", "3")], vec![("ssm_hierarchy", "on")]] {
        let default = first_similarities(&setup);
        let mut with8 = setup.clone();
        with8.push(("bins", "8"));
        let eight = first_similarities(&with8);
        assert!(default.len() >= 3, "{setup:?}: stages {default:?}");
        assert_eq!(default.len(), eight.len(), "{setup:?}");
        for (d, e) in default.iter().zip(&eight) {
            assert_eq!((d.0, d.1), (e.0, e.1), "{setup:?}");
            assert!(
                (d.2 - e.2).abs() > 1e-9 * d.2.abs().max(1.0),
                "{setup:?}: the stage at level {} with {} parameters scores {} with bins=8 \
                 and with the default: it did not get the AM's parameter",
                d.0,
                d.1,
                d.2
            );
        }
        // Setting the default explicitly changes nothing.
        let mut with16 = setup.clone();
        with16.push(("bins", "16"));
        assert_eq!(first_similarities(&with16), default, "{setup:?}");
    }
}

#[test]
fn an_illumination_model_recovers_a_known_warp_with_every_gradient_method() {
    // SSD under each illumination model (the tracker option `ilm`) with every search method and
    // SSM: the gradient methods recover the warp as SSD alone does (within 0.1 px in 19 of 20
    // trials; REGTRACK_FULL_TESTS=1: every SSM with both models, 100 trials); the sampling
    // methods that need a patch embedding are refused with the reason. Other AMs refuse it.
    let trials = if full_tests() { 100 } else { 20 };
    let mut combos = Vec::new();
    for s in sm::REGISTRY {
        for m in ssm::REGISTRY {
            for ilm in ["pgb", "rbf"] {
                // By default pgb on 2, 4 and 8 DOF and rbf on the homography; every pair with
                // REGTRACK_FULL_TESTS=1.
                let quick = match ilm {
                    "pgb" => ["translation", "similitude", "homography"].contains(&m.name),
                    _ => m.name == "homography",
                };
                if !full_tests() && !quick {
                    continue;
                }
                let mut spec = TrackerSpec::from_names(s.name, "ssd", m.name).unwrap();
                spec.set_param("ilm", ilm).unwrap();
                match Tracker::new(&spec) {
                    Ok(_) => combos.push((spec, ilm, sampling(s.name))),
                    Err(e) => {
                        let msg = e.to_string();
                        assert!(msg.contains("needs"), "{} {ilm}: {msg}", spec.label());
                    }
                }
            }
        }
    }
    assert!(combos.iter().filter(|(_, _, sampled)| !sampled).count() >= 20);
    let failures: Vec<(String, usize)> = combos
        .par_iter()
        .map(|(spec, ilm, sampled)| {
            // The sampling methods (PF: thousands of evaluations a frame) on 3 trials.
            let (n, tol) = if *sampled { (3, 3.0) } else { (trials, 0.1) };
            let ok = converged(spec, 2.0, n, tol, 42);
            (format!("{} ilm={ilm}", spec.label()), n - ok)
        })
        .filter(|(label, missed)| *missed > trials / 20 || (label.starts_with("pf") && *missed > 0))
        .collect();
    assert!(failures.is_empty(), "missed trials: {failures:?}");
    let mut zncc = TrackerSpec::from_names("esm", "zncc", "homography").unwrap();
    zncc.set_param("ilm", "pgb").unwrap();
    let err = Tracker::new(&zncc).unwrap_err().to_string();
    assert!(
        err.contains("least-squares") && err.contains("zncc"),
        "{err}"
    );
}

/// The frequency of convergence (Baker and Matthews' experiment) falls as the starts move
/// further off, repeats itself from its seed, and shows the default pyramid's wider basin;
/// `regtrack converge` writes its table and figure.
#[test]
fn the_frequency_of_convergence_falls_with_the_perturbation_and_the_pyramid_widens_it() {
    use regtrack::converge::{ConvergeSpec, frequency_of_convergence};
    let img = regtrack::imaging::Frame8::Gray(crate::common::texture("skimage_coffee.png"));
    let truth = regtrack::geometry::Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    let c = ConvergeSpec {
        sigmas: vec![1.0, 20.0],
        starts: 20,
        ..ConvergeSpec::default()
    };
    let mut paper = TrackerSpec::from_names("iclk", "ssd", "homography").unwrap();
    crate::common::paper_settings(&mut paper);
    let defaults = TrackerSpec::from_names("iclk", "ssd", "homography").unwrap();
    let p = frequency_of_convergence(&paper, &img, &truth, &c).unwrap();
    assert_eq!(
        p,
        frequency_of_convergence(&paper, &img, &truth, &c).unwrap()
    );
    let d = frequency_of_convergence(&defaults, &img, &truth, &c).unwrap();
    assert!(p.points[0].1 >= 0.95, "{p:?}");
    assert!(p.points[1].1 < p.points[0].1, "{p:?}");
    assert!(
        d.points[1].1 > p.points[1].1,
        "pyramid {d:?} vs paper {p:?}"
    );
    // The converged end close to the truth.
    assert!(p.points[0].2 < 0.5, "{p:?}");
    // The command: a table on stdout, the CSV and both figures on disk.
    let dir = crate::common::TempDir::new("converge");
    let seq = dir.path().join("data");
    crate::cli::succeed(crate::cli::synth(
        "ucsb_bricks_rt.txt",
        &seq,
        "rt",
        &["--frames", "2"],
    ));
    let out = dir.path().join("out");
    let o = crate::cli::regtrack(&[
        "converge",
        "--seq",
        seq.join("rt.txt").to_str().unwrap(),
        "--sm",
        "iclk,esm",
        "--am",
        "ssd",
        "--starts",
        "4",
        "--sigmas",
        "1,6",
        "--out",
        out.to_str().unwrap(),
    ]);
    let text = String::from_utf8_lossy(&o.stdout).to_string();
    crate::cli::succeed(o);
    assert!(
        text.contains("iclk_ssd_homography") && text.contains("esm_ssd_homography"),
        "{text}"
    );
    let csv = std::fs::read_to_string(out.join("convergence.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 2 * 2, "{csv}");
    assert!(out.join("convergence.svg").is_file() && out.join("convergence.png").is_file());
}

/// Selective pixel integration (`spi=gradient`, half the grid, on the homography; a mask over
/// a third of the target on the affine warp): every AM that scores any selection of points,
/// with every gradient method (and the sampling ones with REGTRACK_FULL_TESTS=1), recovers a
/// known warp as on the whole grid (ICLK on MI and CCRE within 0.3 px instead of 0.1); the
/// AMs that read the patch as the whole grid (NGF, LSCV, an illumination model) are refused
/// with the reason. In colour and on the descriptor fields too (each channel's part keeps the
/// same points).
#[test]
fn every_am_recovers_a_known_warp_reading_part_of_the_grid() {
    let trials = if full_tests() { 100 } else { 20 };
    let mut combos = Vec::new();
    let mut refused = Vec::new();
    for s in sm::REGISTRY {
        let sampled = sampling(s.name);
        if sampled && !full_tests() {
            continue;
        }
        for a in am::REGISTRY {
            for (k, how) in [
                &[("spi", "gradient")][..],
                &[("spi_mask_right", "0.35"), ("spi_mask_bottom", "1")][..],
            ]
            .into_iter()
            .enumerate()
            {
                let m = if k == 0 { "homography" } else { "affine" };
                let Ok(mut spec) = TrackerSpec::from_names(s.name, a.name, m) else {
                    continue;
                };
                for (name, value) in how {
                    spec.set_param(name, value).unwrap();
                }
                match Tracker::new(&spec) {
                    Ok(_) => combos.push((spec, sampled)),
                    Err(e) => {
                        let msg = e.to_string();
                        assert!(
                            msg.contains("selective pixel integration") && msg.contains(a.name),
                            "{}: {msg}",
                            spec.label()
                        );
                        refused.push(a.name);
                    }
                }
            }
        }
    }
    refused.sort();
    refused.dedup();
    assert_eq!(refused, ["lscv", "ngf"]);
    // Several channels (colour, descriptor fields): the same points of each channel's part.
    for (sm, am) in [("esm", "ssd"), ("fclk", "zncc"), ("iclk", "ssd")] {
        for channels in ["rgb", "df"] {
            let mut spec = TrackerSpec::from_names(sm, am, "homography").unwrap();
            spec.set_param("spi", "gradient").unwrap();
            spec.set_param("channels", channels).unwrap();
            combos.push((spec, false));
        }
    }
    let failures: Vec<(String, usize, f64)> = combos
        .par_iter()
        .map(|(spec, sampled)| {
            let r = spec.registration().unwrap();
            // ICLK's template-side step on the histogram models converges less closely on part
            // of the grid: every trial within 0.3 px, 0 to 11 of 20 within 0.1 (measured).
            let template_side = matches!(r.sm.as_str(), "iclk" | "nnic");
            let histogram = matches!(r.am.as_str(), "mi" | "ccre");
            let (n, tol) = match (*sampled, template_side && histogram) {
                (true, _) => (10, 3.0),
                (false, true) => (trials, 0.3),
                (false, false) => (trials, 0.1),
            };
            let bound = optimum_bias(&r.sm, &r.am, &r.ssm);
            let (ok, bias) = recovered(spec, 2.0, n, tol, 42, bound.is_some());
            let missed = n - ok;
            let far = bound.map_or(0.0, |b| if bias > b { bias } else { 0.0 });
            (spec.label(), missed, far)
        })
        .filter(|(_, missed, far)| *missed > trials / 20 || *far > 0.0)
        .collect();
    assert!(failures.is_empty(), "missed trials: {failures:?}");
    // An illumination model reads the grid's cells.
    let mut ilm = TrackerSpec::from_names("esm", "ssd", "homography").unwrap();
    ilm.set_param("ilm", "pgb").unwrap();
    ilm.set_param("spi", "gradient").unwrap();
    let err = Tracker::new(&ilm).unwrap_err().to_string();
    assert!(err.contains("illumination model"), "{err}");
}

/// Colour (`channels = rgb`, the texture's three channels, the AM on them stacked and channel
/// by channel): every AM with every gradient method (and the sampling ones with
/// REGTRACK_FULL_TESTS=1) recovers a known warp of the 8-DOF homography as on grey.
#[test]
fn every_am_recovers_a_known_warp_in_colour() {
    recovers_on_channels("rgb", &["stacked", "per_channel"], 3);
}

/// Descriptor fields (`channels = df`, the grey texture's derivatives split by sign and
/// smoothed, the AM on the four stacked; channel by channel too with REGTRACK_FULL_TESTS=1):
/// every AM with every gradient method (the sampling ones with REGTRACK_FULL_TESTS=1) recovers a
/// known warp of the 8-DOF homography as on grey.
#[test]
fn every_am_recovers_a_known_warp_on_descriptor_fields() {
    let models: &[&str] = if full_tests() {
        &["stacked", "per_channel"]
    } else {
        &["stacked"]
    };
    recovers_on_channels("df", models, 1);
}

/// Every AM x SM on the homography with `channels` and each of `models` recovers a known warp
/// (`reads`: the frame's channels the tracker reads).
fn recovers_on_channels(channels: &str, models: &[&str], reads: usize) {
    let trials = if full_tests() { 100 } else { 20 };
    let mut combos = Vec::new();
    for s in sm::REGISTRY {
        let sampled = sampling(s.name);
        if sampled && !full_tests() {
            continue;
        }
        for a in am::REGISTRY {
            let Ok(mut spec) = TrackerSpec::from_names(s.name, a.name, "homography") else {
                continue;
            };
            spec.set_param("channels", channels).unwrap();
            match Tracker::new(&spec) {
                Ok(t) => assert_eq!(t.channels(), reads),
                // A histogram of grey levels cannot compare descriptor fields: refused, with
                // the reason.
                Err(e) if channels == "df" && matches!(a.name, "mi" | "ccre") => {
                    assert!(e.to_string().contains("channels=df"), "{e}");
                    continue;
                }
                Err(e) => panic!("{}: {e}", spec.label()),
            }
            for model in models {
                spec.set_param("channel_model", model).unwrap();
                combos.push((spec.clone(), sampled));
            }
        }
    }
    let failures: Vec<(String, usize, f64)> = combos
        .par_iter()
        .map(|(spec, sampled)| {
            let r = spec.registration().unwrap();
            let (n, tol) = if *sampled { (10, 3.0) } else { (trials, 0.1) };
            let bound = optimum_bias(&r.sm, &r.am, &r.ssm);
            let (ok, bias) = recovered(spec, 2.0, n, tol, 42, bound.is_some());
            let far = bound.map_or(0.0, |b| if bias > b { bias } else { 0.0 });
            (spec.label(), n - ok, far)
        })
        .filter(|(_, missed, far)| *missed > trials / 20 || *far > 0.0)
        .collect();
    assert!(failures.is_empty(), "missed trials: {failures:?}");
}
