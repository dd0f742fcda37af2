//! The cost landscape: the swept similarity peaks at the truth, and the analytic gradient
//! matches the numeric one.

use crate::common::texture;
use regtrack::geometry::{Point, Quad};
use regtrack::landscape::LandscapeSpec;
use regtrack::tracker::{FrameInput, Tracker, TrackerSpec};

#[test]
fn the_landscape_peaks_at_the_truth_and_its_gradients_agree() {
    let img = texture("skimage_coffee.png");
    let truth = Quad::from_rect(250.0, 150.0, 100.0, 100.0);
    for (am, ssm) in [
        ("ssd", "homography"),
        ("zncc", "similitude"),
        ("ncc", "translation"),
    ] {
        let mut spec = TrackerSpec::from_names("esm", am, ssm).unwrap();
        // The paper's smoothing: the analytic gradient takes the image's gradient at the pixels
        // (central differences) interpolated, the numeric one differences the interpolated
        // values; the two agree to 6 % on a smooth image, and part further as it sharpens (at
        // the default sigma of 0.7, 10 % for ZNCC-similitude here even with a 0.06 px step).
        spec.set_param("blur_sigma", "3").unwrap();
        let mut t = Tracker::new(&spec).unwrap();
        t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
        // A curve along each of the first two parameters, and a map of both.
        for axes in [vec![0], vec![1], vec![0, 1]] {
            let l = t
                .landscape(
                    FrameInput::Gray8(&img),
                    &truth,
                    &LandscapeSpec {
                        axes: axes.clone(),
                        radius: 4.0,
                        steps: 21,
                    },
                )
                .unwrap()
                .unwrap();
            assert_eq!(l.values.len(), 21usize.pow(axes.len() as u32));
            for b in l.best() {
                assert!(b.abs() < 1e-9, "{am} {ssm} {axes:?}: best at {b} px");
            }
            // At the optimum the slopes at the centre are noise next to the slope a pixel
            // away (what the panel says instead of showing a gap as a wrong derivative).
            for ((a, n), s) in l.analytic.iter().zip(&l.numeric).zip(l.slope_scale()) {
                assert!(s > 0.0, "{am} {ssm} {axes:?}: flat");
                assert!(
                    a.abs().max(n.abs()) < 0.02 * s,
                    "{am} {ssm} {axes:?}: slopes {a}, {n} against {s} a px away"
                );
            }
        }
        // Off the optimum the gradient is not zero; analytic and numeric agree (to 6 % of the
        // gradient's size: the analytic one uses the sampled image gradients, the numeric one
        // differences of the interpolated similarity).
        let off = truth.map(|p| Point::new(p.x + 1.3, p.y - 0.8));
        let pairs: Vec<(f64, f64)> = (0..2)
            .map(|k| {
                let l = t
                    .landscape(
                        FrameInput::Gray8(&img),
                        &off,
                        &LandscapeSpec {
                            axes: vec![k],
                            radius: 3.0,
                            steps: 11,
                        },
                    )
                    .unwrap()
                    .unwrap();
                (l.analytic[0], l.numeric[0])
            })
            .collect();
        let size = pairs.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
        assert!(size > 0.0, "{am} {ssm}: flat");
        for (k, (a, n)) in pairs.iter().enumerate() {
            assert!(
                (a - n).abs() <= 0.06 * size,
                "{am} {ssm} parameter {k}: analytic {a} vs numeric {n}"
            );
        }
    }
    // Bad axes are refused with the reason.
    let spec = TrackerSpec::from_names("iclk", "ssd", "translation").unwrap();
    let mut t = Tracker::new(&spec).unwrap();
    t.initialize(FrameInput::Gray8(&img), &truth).unwrap();
    let e = t
        .landscape(
            FrameInput::Gray8(&img),
            &truth,
            &LandscapeSpec {
                axes: vec![5],
                ..LandscapeSpec::default()
            },
        )
        .unwrap()
        .unwrap_err();
    assert!(e.to_string().contains("2 parameters"), "{e}");
}
