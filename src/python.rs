//! The Python module `regtrack` (feature `python`; built by maturin from `pyproject.toml`).
//!
//! A thin layer over the library: trackers are built from the same registries and parameter
//! definitions as the command line ([`TrackerSpec::from_names`], [`TrackerSpec::set_param`]),
//! so nothing is listed twice. Frames are numpy arrays (`uint8` or `float32`, grey `(H, W)` or
//! OpenCV's BGR `(H, W, 3)`, any strides); corners are `(4, 2)` arrays. The GIL is released while
//! a tracker initialises or updates, so trackers in several Python threads run in parallel.
//!
//! Errors: a frame or corners of the wrong type or shape, or non-finite corners, raise
//! `ValueError` naming what was expected; a library error raises `regtrack.Error` with the
//! command line's text. A loss of track is a status, not an exception.

use crate::geometry::{Point, Quad};
use crate::imaging::{ColourU8, GrayF32, GrayU8, Image, luma};
use crate::observe::{NoObserver, Recorder};
use crate::status::TrackStatus;
use crate::tracker::{FrameInput, Tracker, TrackerSpec};
use numpy::{
    AllowTypeChange, PyArray1, PyArray2, PyArray3, PyArrayLike2, PyArrayMethods,
    PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

pyo3::create_exception!(
    regtrack,
    Error,
    PyException,
    "An error of the regtrack library (an unknown method, a parameter out of range, a region a \
     tracker cannot start from...), with the command line's message."
);

fn library_error(e: crate::Error) -> PyErr {
    Error::new_err(e.to_string())
}

/// A frame converted for the tracker, in buffers the tracker object keeps (no allocation per
/// frame once their size is known).
#[derive(Default)]
struct FrameBuffers {
    gray: GrayU8,
    float: GrayF32,
    /// A BGR frame's channels, for a tracker that reads colour.
    colour: ColourU8,
    /// Which one holds the frame.
    is_float: bool,
    is_colour: bool,
}

impl FrameBuffers {
    fn input(&self) -> FrameInput<'_> {
        if self.is_colour {
            FrameInput::Colour(&self.colour)
        } else if self.is_float {
            FrameInput::Gray32(&self.float)
        } else {
            FrameInput::Gray8(&self.gray)
        }
    }

    /// Copies (and for colour, converts to grey) a numpy frame.
    fn load(&mut self, frame: &Bound<'_, PyAny>) -> PyResult<()> {
        self.load_as(frame, false)
    }

    /// [`FrameBuffers::load`]; with `colour` a BGR frame (OpenCV's order) keeps its channels
    /// as well (a float one's values rounded into 0..255), for a tracker with `channels = rgb`.
    fn load_as(&mut self, frame: &Bound<'_, PyAny>, colour: bool) -> PyResult<()> {
        let expected = "a numpy array of uint8 or float32, grey (H, W) or BGR (H, W, 3)";
        self.is_colour = false;
        if colour && let Some(done) = self.load_colour(frame, expected)? {
            self.is_colour = done;
            if done {
                return Ok(());
            }
        }
        if let Ok(a) = frame.extract::<PyReadonlyArrayDyn<'_, u8>>() {
            self.is_float = false;
            return copy_frame(&mut self.gray, &a, expected, |bgr| {
                luma(bgr[2], bgr[1], bgr[0])
            });
        }
        if let Ok(a) = frame.extract::<PyReadonlyArrayDyn<'_, f32>>() {
            self.is_float = true;
            // BT.601, as `luma` for 8-bit frames.
            return copy_frame(&mut self.float, &a, expected, |bgr| {
                0.299 * bgr[2] + 0.587 * bgr[1] + 0.114 * bgr[0]
            });
        }
        let what = match frame.getattr("dtype") {
            Ok(d) => format!("an array of dtype {d}"),
            Err(_) => format!("a {}", frame.get_type().name()?),
        };
        Err(PyValueError::new_err(format!(
            "frame must be {expected}, got {what}"
        )))
    }

    /// A BGR frame (uint8 or float32) into `colour`: `Some(true)` when it was one, `Some(false)`
    /// for a grey frame (read as grey), `None` for another dtype.
    fn load_colour(&mut self, frame: &Bound<'_, PyAny>, expected: &str) -> PyResult<Option<bool>> {
        if let Ok(a) = frame.extract::<PyReadonlyArrayDyn<'_, u8>>() {
            return copy_colour(&mut self.colour, &a, expected, |v| v);
        }
        if let Ok(a) = frame.extract::<PyReadonlyArrayDyn<'_, f32>>() {
            return copy_colour(&mut self.colour, &a, expected, |v| {
                v.round().clamp(0.0, 255.0) as u8
            });
        }
        Ok(None)
    }
}

/// Copies a BGR frame's channels (as bytes by `byte`) and its grey into `dst` (`Some(true)`),
/// or leaves a grey frame (`Some(false)`). The buffers are reused.
fn copy_colour<T: numpy::Element + Copy>(
    dst: &mut ColourU8,
    a: &PyReadonlyArrayDyn<'_, T>,
    expected: &str,
    byte: impl Fn(T) -> u8,
) -> PyResult<Option<bool>> {
    let (h, w, c) = shape_of(a.shape(), expected)?;
    if c != 3 {
        return Ok(Some(false));
    }
    for img in dst.channels.iter_mut().chain([&mut dst.gray]) {
        fill(img, w, h);
    }
    let view = a.as_array();
    let standard = view.as_standard_layout();
    let flat = standard.as_slice().expect("standard layout");
    let [r, g, b] = &mut dst.channels;
    for (i, bgr) in flat.chunks_exact(3).enumerate() {
        let (vb, vg, vr) = (byte(bgr[0]), byte(bgr[1]), byte(bgr[2]));
        (r.data[i], g.data[i], b.data[i]) = (vr, vg, vb);
        dst.gray.data[i] = luma(vr, vg, vb);
    }
    Ok(Some(true))
}

/// Copies a grey frame into `dst`, or converts a BGR one with `grey` (a C-ordered frame is read
/// as it is; another layout is made C-ordered first).
fn copy_frame<T: numpy::Element + Copy + Default>(
    dst: &mut Image<T>,
    a: &PyReadonlyArrayDyn<'_, T>,
    expected: &str,
    grey: impl Fn(&[T]) -> T,
) -> PyResult<()> {
    let (h, w, c) = shape_of(a.shape(), expected)?;
    fill(dst, w, h);
    let view = a.as_array();
    let standard = view.as_standard_layout();
    let flat = standard.as_slice().expect("standard layout");
    if c == 1 {
        dst.data.copy_from_slice(flat);
    } else {
        for (v, bgr) in dst.data.iter_mut().zip(flat.chunks_exact(3)) {
            *v = grey(bgr);
        }
    }
    Ok(())
}

/// `(height, width, channels)` of a frame's shape: `(H, W)`, `(H, W, 1)` or `(H, W, 3)`.
fn shape_of(shape: &[usize], expected: &str) -> PyResult<(usize, usize, usize)> {
    let (h, w, c) = match shape {
        [h, w] => (*h, *w, 1),
        [h, w, 1] => (*h, *w, 1),
        [h, w, 3] => (*h, *w, 3),
        _ => {
            return Err(PyValueError::new_err(format!(
                "frame must be {expected}, got shape {shape:?}"
            )));
        }
    };
    if h == 0 || w == 0 {
        return Err(PyValueError::new_err(format!(
            "frame is empty: shape {shape:?}"
        )));
    }
    Ok((h, w, c))
}

fn fill<T: Default + Clone>(img: &mut Image<T>, w: usize, h: usize) {
    img.width = w;
    img.height = h;
    img.data.resize(w * h, T::default());
}

/// Corners `(4, 2)` (array, list or tuple; any numeric dtype), finite.
fn quad_from(corners: &Bound<'_, PyAny>) -> PyResult<Quad> {
    let expected = "corners must be 4 points (x, y): an array of shape (4, 2)";
    let a: PyArrayLike2<'_, f64, AllowTypeChange> = corners
        .extract()
        .map_err(|_| PyValueError::new_err(format!("{expected}, got {corners}")))?;
    if a.shape() != [4, 2] {
        return Err(PyValueError::new_err(format!(
            "{expected}, got shape {:?}",
            a.shape()
        )));
    }
    let v = a.as_array();
    let q = Quad([0, 1, 2, 3].map(|i| Point::new(v[[i, 0]], v[[i, 1]])));
    if !q.is_finite() {
        return Err(PyValueError::new_err(format!(
            "corners must be finite, got {q}"
        )));
    }
    Ok(q)
}

fn quad_to<'py>(py: Python<'py>, q: &Quad) -> Bound<'py, PyArray2<f64>> {
    let rows: Vec<Vec<f64>> = q.0.iter().map(|p| vec![p.x, p.y]).collect();
    PyArray2::from_vec2(py, &rows).expect("4 rows of 2")
}

/// `f()` and the time it took, µs.
fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let started = std::time::Instant::now();
    let out = f();
    (out, started.elapsed().as_secs_f64() * 1e6)
}

fn status_text(s: &TrackStatus) -> String {
    match s {
        TrackStatus::Uninitialized => "uninitialized".into(),
        TrackStatus::Tracking => "tracking".into(),
        TrackStatus::Lost(r) => format!("lost: {r}"),
    }
}

/// A value given as a keyword argument, in the typed form parameters are written in.
fn param_text(v: &Bound<'_, PyAny>) -> PyResult<String> {
    if let Ok(b) = v.extract::<bool>() {
        return Ok(if b { "1" } else { "0" }.into());
    }
    Ok(v.str()?.to_string())
}

/// A tracker: a registration tracker (search method, appearance model, state space model) or a
/// whole tracker (`tracker="kcf"`), with any of its parameters as keyword arguments.
///
/// >>> t = regtrack.Tracker("esm", "zncc", "homography", levels=3)
/// >>> t.initialize(frame, corners)          # corners: (4, 2), clockwise from top-left
/// >>> corners, status = t.update(next_frame)
#[pyclass(name = "Tracker", module = "regtrack")]
pub struct PyTracker {
    /// Behind a mutex so that the object is `Sync` (a Python object may be shared between
    /// threads); `&mut self` methods reach it without locking.
    inner: std::sync::Mutex<Tracker>,
    frames: FrameBuffers,
    recorder: Option<Recorder>,
    /// The library's own time in the last `initialize` or `update` (µs).
    last_us: f64,
    /// The size of the frame the tracker was initialised on: every frame it tracks has it.
    size: Option<(usize, usize)>,
}

/// A C-ordered, non-empty grey `uint8` array as an image where it is (numpy's buffer, read
/// without a copy), or `None` for any other array.
fn gray_u8_view<'a>(
    a: &'a numpy::PyReadonlyArray2<'_, u8>,
) -> Option<crate::imaging::ImageRef<'a, u8>> {
    let data = a.as_slice().ok().filter(|_| a.is_c_contiguous())?;
    let [h, w] = [a.shape()[0], a.shape()[1]];
    crate::imaging::ImageRef::new(w, h, data).filter(|_| w > 0 && h > 0)
}

impl PyTracker {
    /// Runs `f` on the tracker and `frame` with the GIL released: a C-ordered grey `uint8`
    /// frame is read where it is (numpy's buffer; do not write to it from another thread
    /// meanwhile), any other is first converted into the tracker object's buffers.
    fn with_frame<R: Send>(
        &mut self,
        py: Python<'_>,
        frame: &Bound<'_, PyAny>,
        f: impl FnOnce(&mut Tracker, FrameInput<'_>) -> R + Send,
    ) -> PyResult<(R, f64)> {
        let t = self.inner.get_mut().unwrap_or_else(|e| e.into_inner());
        if let Ok(a) = frame.extract::<numpy::PyReadonlyArray2<'_, u8>>()
            && let Some(view) = gray_u8_view(&a)
        {
            return Ok(py.detach(|| timed(|| f(t, FrameInput::View8(view)))));
        }
        self.frames.load_as(frame, t.channels() == 3)?;
        let frames = &self.frames;
        Ok(py.detach(|| timed(|| f(t, frames.input()))))
    }

    fn tracker(&self) -> std::sync::MutexGuard<'_, Tracker> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
    fn tracker_mut(&mut self) -> &mut Tracker {
        self.inner.get_mut().unwrap_or_else(|e| e.into_inner())
    }
}

#[pymethods]
impl PyTracker {
    /// Builds a tracker. Without `sm` and `am`, the default tracker (FCLK-SSD with the second
    /// hypothesis `second=fclk_zncc` and `escalate=on`; `regtrack list` names it). Keyword
    /// arguments set parameters by name (`regtrack.list_methods()` lists them), checked against
    /// their definitions.
    #[new]
    #[pyo3(signature = (sm=None, am=None, ssm=None, *, tracker=None, **params))]
    fn new(
        sm: Option<&str>,
        am: Option<&str>,
        ssm: Option<&str>,
        tracker: Option<&str>,
        params: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let d = crate::spec::DEFAULT_TRACKER;
        let mut spec = match tracker {
            Some(name) => {
                if sm.is_some() || am.is_some() || ssm.is_some() {
                    return Err(PyValueError::new_err(format!(
                        "give either a whole tracker ('{name}') or sm, am, ssm, not both"
                    )));
                }
                TrackerSpec::whole(name)
            }
            None => crate::tracker::one(sm, am, ssm.unwrap_or(d[2])),
        }
        .map_err(library_error)?;
        if let Some(params) = params {
            for (k, v) in params.iter() {
                let name: String = k.extract()?;
                spec.set_param(&name, &param_text(&v)?)
                    .map_err(library_error)?;
            }
        }
        Ok(PyTracker {
            inner: std::sync::Mutex::new(Tracker::new(&spec).map_err(library_error)?),
            frames: FrameBuffers::default(),
            recorder: None,
            last_us: 0.0,
            size: None,
        })
    }

    /// Starts tracking `corners` (4 x 2) in `frame`.
    fn initialize(
        &mut self,
        py: Python<'_>,
        frame: &Bound<'_, PyAny>,
        corners: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let q = quad_from(corners)?;
        let (r, us) = self.with_frame(py, frame, |t, input| {
            t.initialize(input, &q).map(|()| input.size())
        })?;
        self.last_us = us;
        self.size = None;
        self.size = Some(r.map_err(library_error)?);
        Ok(())
    }

    /// Tracks one frame; returns `(corners, status)`: the corners (4 x 2; when lost, the last
    /// good ones) and `"tracking"`, `"lost: <reason>"` or `"uninitialized"`. With
    /// `record=True`, the frame's iterations are kept for [`Tracker.iterations`].
    #[pyo3(signature = (frame, record=false))]
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        frame: &Bound<'py, PyAny>,
        record: bool,
    ) -> PyResult<(Bound<'py, PyArray2<f64>>, String)> {
        let mut rec = if record {
            Some(self.recorder.take().unwrap_or_default())
        } else {
            None
        };
        let expected = self.size;
        let (out, us) = self.with_frame(py, frame, |t, input| {
            // A frame of another size than the first: the corners would be read on another
            // picture (a camera that changed its mode, a frame cropped by mistake).
            if let Some(e) = expected
                && input.size() != e
            {
                return Err((input.size(), e));
            }
            Ok(match rec.as_mut() {
                Some(r) => t.update(input, r),
                None => t.update(input, &mut NoObserver),
            })
        })?;
        self.recorder = rec;
        let out = out.map_err(|((w, h), (w0, h0))| {
            PyValueError::new_err(format!(
                "the frame is {w}x{h} and the tracker was initialised on a {w0}x{h0} frame: \
                 initialize it again for frames of another size"
            ))
        })?;
        self.last_us = us;
        Ok((quad_to(py, &out.corners), status_text(&out.status)))
    }

    /// The current corners (4 x 2).
    #[getter]
    fn corners<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        quad_to(py, &self.tracker().corners())
    }

    /// A non-rigid tracker's (`ssm="spline"`, `"tps"`...) warp as a lattice over its target:
    /// `(side, side, 2)` image points, row by row; `None` for the others.
    #[getter]
    fn warped_grid<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray3<f64>>>> {
        let Some(grid) = self.tracker().warped_grid() else {
            return Ok(None);
        };
        let rows: Vec<Vec<Vec<f64>>> = grid
            .points
            .chunks(grid.side.max(1))
            .map(|row| row.iter().map(|p| vec![p.x, p.y]).collect())
            .collect();
        PyArray3::from_vec3(py, &rows)
            .map(Some)
            .map_err(|e| Error::new_err(e.to_string()))
    }

    /// `"tracking"`, `"lost: <reason>"` or `"uninitialized"`.
    #[getter]
    fn status(&self) -> String {
        status_text(&self.tracker().status())
    }

    /// Moves the tracker to `corners` (4 x 2), keeping its template; resumes a lost tracker.
    fn set_corners(&mut self, corners: &Bound<'_, PyAny>) -> PyResult<()> {
        let q = quad_from(corners)?;
        self.tracker_mut().set_corners(&q).map_err(library_error)
    }

    /// The time the library itself took in the last `initialize` or `update`, µs (the rest of
    /// a call's time is the binding's: reading the frame, the GIL, the result arrays).
    #[getter]
    fn last_update_us(&self) -> f64 {
        self.last_us
    }

    /// The tracker's label (`sm_am_ssm`, or a whole tracker's name).
    #[getter]
    fn label(&self) -> String {
        self.tracker().spec().label()
    }

    /// The iterations of the last `update(frame, record=True)`, as numpy arrays: `level`,
    /// `similarity` (before each step), `step` (the corners' change, px), `params` (n x DOF,
    /// normalised frame) and `corners` (n x 4 x 2). `None` when the last update did not record.
    #[getter]
    fn iterations<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(rec) = &self.recorder else {
            return Ok(None);
        };
        let its = &rec.iterations;
        let d = PyDict::new(py);
        d.set_item(
            "level",
            PyArray1::from_vec(py, its.iter().map(|i| i.level as i64).collect()),
        )?;
        d.set_item(
            "similarity",
            PyArray1::from_vec(py, its.iter().map(|i| i.similarity).collect()),
        )?;
        d.set_item(
            "step",
            PyArray1::from_vec(py, its.iter().map(|i| i.step).collect()),
        )?;
        let dof = its.first().map_or(0, |i| i.params.len());
        let params: Vec<Vec<f64>> = its.iter().map(|i| i.params.clone()).collect();
        d.set_item(
            "params",
            if params.is_empty() {
                PyArray2::<f64>::zeros(py, [0, dof], false)
            } else {
                PyArray2::from_vec2(py, &params).map_err(|e| Error::new_err(e.to_string()))?
            },
        )?;
        let corners: Vec<Vec<Vec<f64>>> = its
            .iter()
            .map(|i| i.corners.0.iter().map(|p| vec![p.x, p.y]).collect())
            .collect();
        d.set_item(
            "corners",
            if corners.is_empty() {
                PyArray3::<f64>::zeros(py, [0, 4, 2], false)
            } else {
                PyArray3::from_vec3(py, &corners).map_err(|e| Error::new_err(e.to_string()))?
            },
        )?;
        Ok(Some(d))
    }

    fn __repr__(&self) -> String {
        format!(
            "regtrack.Tracker('{}', status='{}')",
            self.label(),
            self.status()
        )
    }
}

/// A frame (grey `H x W`, or BGR `H x W x 3`) and its ground truth (`4 x 2`, `None` when not
/// annotated).
type FrameAndTruth<'py> = (Bound<'py, PyAny>, Option<Bound<'py, PyArray2<f64>>>);

/// A sequence (any layout `regtrack track --seq` reads: MTF, a folder of images, POT), as
/// `(frame, ground_truth)` pairs: the frame as a grey `uint8` array `(H, W)` (with
/// `colour=True`, BGR `(H, W, 3)` as OpenCV reads it, for a tracker with `channels='rgb'`), the
/// ground truth as `(4, 2)` corners or `None` where the frame is not annotated.
///
/// >>> seq = regtrack.Sequence("data/bookI.txt")
/// >>> for frame, gt in seq: ...
#[pyclass(name = "Sequence", module = "regtrack")]
pub struct PySequence {
    seq: crate::dataset::Sequence,
    colour: bool,
}

#[pymethods]
impl PySequence {
    #[new]
    #[pyo3(signature = (path, *, colour=false))]
    fn new(path: std::path::PathBuf, colour: bool) -> PyResult<Self> {
        Ok(PySequence {
            seq: crate::dataset::Sequence::open(&path).map_err(library_error)?,
            colour,
        })
    }

    /// The sequence's name.
    #[getter]
    fn name(&self) -> String {
        self.seq.name.clone()
    }

    /// What the ground truth held that could be read around (each naming file and line).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.seq.warnings.clone()
    }

    /// Every frame's ground truth, `(n, 4, 2)`, NaN where a frame is not annotated.
    #[getter]
    fn ground_truth<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let rows: Vec<Vec<Vec<f64>>> = (0..self.seq.len())
            .map(|i| match self.seq.ground_truth(i) {
                Some(q) => q.0.iter().map(|p| vec![p.x, p.y]).collect(),
                None => vec![vec![f64::NAN; 2]; 4],
            })
            .collect();
        PyArray3::from_vec3(py, &rows).map_err(|e| Error::new_err(e.to_string()))
    }

    fn __len__(&self) -> usize {
        self.seq.len()
    }

    /// Frame `i` and its ground truth (negative indices count from the end).
    fn __getitem__<'py>(&self, py: Python<'py>, i: isize) -> PyResult<FrameAndTruth<'py>> {
        let n = self.seq.len() as isize;
        let k = if i < 0 { i + n } else { i };
        if !(0..n).contains(&k) {
            return Err(pyo3::exceptions::PyIndexError::new_err(format!(
                "frame {i} of a sequence of {n}"
            )));
        }
        let k = k as usize;
        let (seq, colour) = (&self.seq, self.colour);
        let img = py
            .detach(|| seq.load_frame(k, colour))
            .map_err(library_error)?;
        let frame = frame_to_numpy(py, img)?;
        Ok((frame, self.seq.ground_truth(k).map(|q| quad_to(py, &q))))
    }

    fn __iter__(slf: PyRef<'_, Self>) -> SequenceIter {
        SequenceIter {
            seq: slf.into(),
            next: 0,
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "regtrack.Sequence('{}', {} frames)",
            self.seq.name,
            self.seq.len()
        )
    }
}

/// A frame as numpy has it: grey `(H, W)`, or a colour frame as BGR `(H, W, 3)` (OpenCV's
/// order, what the trackers take), `uint8`.
fn frame_to_numpy(py: Python<'_>, frame: crate::imaging::Frame8) -> PyResult<Bound<'_, PyAny>> {
    let shaped = |data: Vec<u8>, shape: &[usize]| {
        numpy::PyArray1::from_vec(py, data)
            .reshape(shape)
            .map(|a| a.into_any())
            .map_err(|e| Error::new_err(e.to_string()))
    };
    match frame {
        crate::imaging::Frame8::Gray(g) => shaped(g.data, &[g.height, g.width]),
        crate::imaging::Frame8::Colour(c) => {
            let bgr = c.rgb_pixels().flat_map(|[r, g, b]| [b, g, r]).collect();
            shaped(bgr, &[c.gray.height, c.gray.width, 3])
        }
    }
}

/// The iterator over a [`PySequence`].
#[pyclass(module = "regtrack")]
pub struct SequenceIter {
    seq: Py<PySequence>,
    next: usize,
}

#[pymethods]
impl SequenceIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&mut self, py: Python<'py>) -> PyResult<Option<FrameAndTruth<'py>>> {
        let seq = self.seq.borrow(py);
        if self.next >= seq.seq.len() {
            return Ok(None);
        }
        self.next += 1;
        seq.__getitem__(py, self.next as isize - 1).map(Some)
    }
}

/// A live source: a V4L2 camera (`"/dev/video0"`) or an FFmpeg test source
/// (`"lavfi:testsrc=size=320x240:rate=30"`), read by `ffmpeg`, as an iterator of grey `uint8`
/// frames `(H, W)` (with `colour=True`, BGR `(H, W, 3)`, for a tracker with `channels='rgb'`),
/// always the newest: frames that arrive while Python works are dropped and
/// counted (`dropped`, after the first). Iteration ends when the source stops (`stopped` says
/// why); a source that stops before its first frame raises `regtrack.Error`. The library's live
/// run ([`crate::dataset::live::LiveRun`], as `regtrack track --camera` and the inspector).
///
/// >>> for frame in regtrack.Camera("/dev/video0", size=(640, 480)): ...
#[pyclass(name = "Camera", module = "regtrack")]
pub struct PyCamera {
    live: Option<crate::dataset::live::LiveRun>,
    dropped: u64,
    stopped: Option<String>,
    /// Frames handed out.
    given: u64,
}

#[pymethods]
impl PyCamera {
    #[new]
    #[pyo3(signature = (source, size=(640, 480), *, colour=false))]
    fn new(source: &str, size: (i64, i64), colour: bool) -> PyResult<Self> {
        let (Ok(w), Ok(h)) = (usize::try_from(size.0), usize::try_from(size.1)) else {
            return Err(PyValueError::new_err(format!(
                "size must be (width, height) in pixels, got ({}, {})",
                size.0, size.1
            )));
        };
        Ok(PyCamera {
            live: Some(
                crate::dataset::live::LiveRun::open(source, w, h, colour).map_err(library_error)?,
            ),
            dropped: 0,
            stopped: None,
            given: 0,
        })
    }

    /// Frames the source sent that were never handed out.
    #[getter]
    fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Why the source stopped (`None` while it runs).
    #[getter]
    fn stopped(&self) -> Option<String> {
        self.stopped.clone()
    }

    /// Stops the source.
    fn close(&mut self) {
        self.live = None;
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__<'py>(&mut self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let Some(live) = self.live.as_mut() else {
            return Ok(None);
        };
        match py.detach(|| live.take(None)) {
            Ok(None) => Ok(None),
            Ok(Some(f)) => {
                self.dropped = live.info().dropped;
                self.given += 1;
                Ok(Some(frame_to_numpy(py, f.image)?))
            }
            Err(e) => {
                self.stopped = Some(e.to_string());
                self.live = None;
                // A source that never gave a frame is an error (no camera there, a bad graph).
                if self.given == 0 {
                    return Err(library_error(e));
                }
                Ok(None)
            }
        }
    }
}

/// Every method of the registries, by kind (`sm`, `am`, `ssm`, `tracker`): a list of dicts with
/// `name`, `aliases` and `description`; the parameters are in `regtrack.list_text()`.
#[pyfunction]
fn list_methods(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    fn entries<'py, B>(
        py: Python<'py>,
        reg: &[crate::registry::Entry<B>],
    ) -> PyResult<Bound<'py, PyList>> {
        let out = PyList::empty(py);
        for e in reg {
            let d = PyDict::new(py);
            d.set_item("name", e.name)?;
            d.set_item("aliases", e.aliases.to_vec())?;
            d.set_item("description", e.description)?;
            out.append(d)?;
        }
        Ok(out)
    }
    let d = PyDict::new(py);
    d.set_item("sm", entries(py, crate::sm::REGISTRY)?)?;
    d.set_item("am", entries(py, crate::am::REGISTRY)?)?;
    d.set_item("ssm", entries(py, crate::ssm::REGISTRY)?)?;
    d.set_item("tracker", entries(py, crate::whole::REGISTRY)?)?;
    Ok(d)
}

/// What `regtrack list` prints: every method with its parameters (name, range, default, help).
#[pyfunction]
fn list_text() -> String {
    crate::catalogue::listing()
}

/// The alignment error of two quads (4 x 2 each): the mean distance of their corners, px.
#[pyfunction]
fn alignment_error(a: &Bound<'_, PyAny>, b: &Bound<'_, PyAny>) -> PyResult<f64> {
    Ok(crate::geometry::alignment_error(
        &quad_from(a)?,
        &quad_from(b)?,
    ))
}

/// A Python object as serde would read it (through its JSON form).
fn from_python<T: serde::de::DeserializeOwned>(obj: &Bound<'_, PyAny>) -> PyResult<T> {
    let text: String = obj
        .py()
        .import("json")?
        .call_method1("dumps", (obj,))?
        .extract()?;
    serde_json::from_str(&text).map_err(|e| PyValueError::new_err(e.to_string()))
}

/// A value made for Python from its JSON form (dicts, lists, numbers, `None` for NaN).
fn to_python<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let text = serde_json::to_string(v).map_err(|e| Error::new_err(e.to_string()))?;
    py.import("json")?.call_method1("loads", (text,))
}

/// Evaluates trackers on a dataset in any of the benchmarks' layouts (docs/benchmarks.md) or on
/// one sequence, as `regtrack eval` does, and returns the summary rows (a list of dicts, one per
/// run and, for trackers on several sequences, one pooled row `sequence="ALL"` and one per
/// challenge factor `"ALL:<factor>"`; the benchmarks' figures `p5`, `p15`, `success_h`,
/// `success_iou` beside SR; `pandas.DataFrame(rows)` takes them as they are). Without `sm`, `am`,
/// `ssm` or `trackers`, the default tracker. With `out`, the run files and summaries are written
/// there (and a later call resumes the runs it finished). Keyword arguments set parameters.
#[pyfunction]
#[pyo3(signature = (dataset, sm=None, am=None, ssm=None, trackers=Vec::new(), seqs=None, out=None, reinit=false, gt_ssm=None, error="alignment", jobs=0, **params))]
#[allow(clippy::too_many_arguments)]
fn eval<'py>(
    py: Python<'py>,
    dataset: std::path::PathBuf,
    sm: Option<Vec<String>>,
    am: Option<Vec<String>>,
    ssm: Option<Vec<String>>,
    trackers: Vec<String>,
    seqs: Option<Vec<String>>,
    out: Option<std::path::PathBuf>,
    reinit: bool,
    gt_ssm: Option<String>,
    error: &str,
    jobs: usize,
    params: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyAny>> {
    let mut assignments = Vec::new();
    if let Some(params) = params {
        for (k, v) in params.iter() {
            assignments.push((k.extract::<String>()?, param_text(&v)?));
        }
    }
    let specs = crate::tracker::select(
        sm.as_deref(),
        am.as_deref(),
        ssm.as_deref(),
        &trackers,
        &assignments,
    )
    .map_err(library_error)?;
    let gt_ssm = match gt_ssm {
        Some(g) if g != crate::eval::OWN_SSM => {
            Some(crate::gt::ssm_key(&g).map_err(library_error)?)
        }
        g => g,
    };
    let options = crate::eval::EvalOptions {
        reinit,
        gt_ssm,
        error: crate::eval::ErrorKind::parse(error).map_err(library_error)?,
        ..crate::eval::EvalOptions::default()
    };
    let rows = py
        .detach(|| -> crate::Result<Vec<crate::eval::Summary>> {
            let sequences = crate::dataset::open_or_discover(&dataset, seqs.as_deref())?;
            let batch = crate::eval::Batch {
                options,
                jobs,
                out: out.as_deref(),
                resume: out.is_some(),
                ..crate::eval::Batch::new(&sequences, &specs)
            };
            let plan = batch.plan();
            let outcome = batch.execute(plan, &|_| {})?;
            let rows = outcome.rows();
            if let Some(out) = out.as_deref() {
                crate::eval::write_summaries(out, &rows)?;
            }
            Ok(rows)
        })
        .map_err(library_error)?;
    to_python(py, &rows)
}

/// Renders a synthetic sequence with exact ground truth in the MTF layout (`out/name.txt`,
/// `out/name/`), as `regtrack synth` does; options are `SynthConfig`'s fields (`noise`,
/// `max_frames`, `step`, `local_light`, `jpeg_quality`, `seed`...). Returns the sequence.
#[pyfunction]
#[pyo3(signature = (texture, motion, out, name, **options))]
fn synth(
    py: Python<'_>,
    texture: std::path::PathBuf,
    motion: std::path::PathBuf,
    out: std::path::PathBuf,
    name: &str,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PySequence> {
    let mut cfg: crate::dataset::synth::SynthConfig = match options {
        Some(o) => from_python(o.as_any())?,
        None => Default::default(),
    };
    cfg.texture = texture;
    cfg.motion = motion;
    let seq = py
        .detach(|| crate::dataset::synth::render_sequence(&cfg, &out, name, &|_, _| {}))
        .map_err(library_error)?;
    Ok(PySequence { seq, colour: false })
}

/// Many patches per frame: N small patches (translation or affine), each tracked by
/// inverse-compositional Lucas-Kanade over one shared pyramid, in parallel over the cores.
/// Keyword arguments are the many-patch parameters (`regtrack.list_text()` lists them).
///
/// >>> pt = regtrack.PatchTracker(warp="affine", size=15)
/// >>> pts = pt.detect(frame, 500)            # (N, 2) Shi-Tomasi corners
/// >>> pt.initialize(frame, pts)
/// >>> centres, tracking = pt.update(next_frame)   # (N, 2) float64, (N,) bool
#[pyclass(name = "PatchTracker", module = "regtrack")]
pub struct PyPatchTracker {
    inner: crate::patches::PatchTracker,
    frames: FrameBuffers,
    last_us: f64,
}

impl PyPatchTracker {
    /// Runs `f` on the tracker and `frame` (grey 8-bit; any other frame is converted first)
    /// with the GIL released.
    fn with_frame<R: Send>(
        &mut self,
        py: Python<'_>,
        frame: &Bound<'_, PyAny>,
        f: impl FnOnce(&mut crate::patches::PatchTracker, crate::imaging::ImageRef<'_, u8>) -> R + Send,
    ) -> PyResult<R> {
        let t = &mut self.inner;
        if let Ok(a) = frame.extract::<numpy::PyReadonlyArray2<'_, u8>>()
            && let Some(view) = gray_u8_view(&a)
        {
            let (r, us) = py.detach(|| timed(|| f(t, view)));
            self.last_us = us;
            return Ok(r);
        }
        self.frames.load(frame)?;
        if self.frames.is_float {
            let fl = &self.frames.float;
            fill(&mut self.frames.gray, fl.width, fl.height);
            for (g, v) in self.frames.gray.data.iter_mut().zip(&fl.data) {
                *g = v.round().clamp(0.0, 255.0) as u8;
            }
        }
        let gray = &self.frames.gray;
        let (r, us) = py.detach(|| timed(|| f(t, gray.into())));
        self.last_us = us;
        Ok(r)
    }

    fn states(&self) -> Vec<crate::patches::PatchState> {
        self.inner.states().copied().collect()
    }
}

/// What `PatchTracker.update` returns.
type CentresAndTracking<'py> = (Bound<'py, PyArray2<f64>>, Bound<'py, PyArray1<bool>>);

/// Points from numpy: an `(N, 2)` array of x, y.
fn points_from(points: &Bound<'_, PyAny>) -> PyResult<Vec<Point>> {
    let a: PyArrayLike2<'_, f64, AllowTypeChange> = points
        .extract()
        .map_err(|_| PyValueError::new_err("points must be an (N, 2) array of x, y"))?;
    let v = a.as_array();
    if v.ncols() != 2 {
        return Err(PyValueError::new_err(format!(
            "points must be an (N, 2) array of x, y, got shape {:?}",
            v.shape()
        )));
    }
    Ok(v.rows()
        .into_iter()
        .map(|r| Point { x: r[0], y: r[1] })
        .collect())
}

fn points_to<'py>(py: Python<'py>, pts: impl Iterator<Item = Point>) -> Bound<'py, PyArray2<f64>> {
    let rows: Vec<Vec<f64>> = pts.map(|p| vec![p.x, p.y]).collect();
    if rows.is_empty() {
        return numpy::PyArray2::zeros(py, [0, 2], false);
    }
    PyArray2::from_vec2(py, &rows).unwrap_or_else(|_| numpy::PyArray2::zeros(py, [0, 2], false))
}

#[pymethods]
impl PyPatchTracker {
    #[new]
    #[pyo3(signature = (**params))]
    fn new(params: Option<&Bound<'_, PyDict>>) -> PyResult<Self> {
        let mut pairs = Vec::new();
        if let Some(params) = params {
            for (k, v) in params.iter() {
                pairs.push((k.extract::<String>()?, param_text(&v)?));
            }
        }
        let prm = crate::patches::PatchParams::parse(&pairs).map_err(library_error)?;
        Ok(PyPatchTracker {
            inner: crate::patches::PatchTracker::new(prm).map_err(library_error)?,
            frames: FrameBuffers::default(),
            last_us: 0.0,
        })
    }

    /// The strongest Shi-Tomasi corners of `frame` where a whole patch fits, at most `max`,
    /// `min_distance` apart; with `region` (corners, 4 x 2), inside it. An `(N, 2)` array.
    #[pyo3(signature = (frame, max=1000, region=None))]
    fn detect<'py>(
        &mut self,
        py: Python<'py>,
        frame: &Bound<'py, PyAny>,
        max: usize,
        region: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let region = region.map(quad_from).transpose()?;
        let pts = self.with_frame(py, frame, |t, f| t.detect(f, max, region.as_ref()))?;
        Ok(points_to(py, pts.into_iter()))
    }

    /// Starts a patch centred on each of `points` (N x 2) in `frame`.
    fn initialize(
        &mut self,
        py: Python<'_>,
        frame: &Bound<'_, PyAny>,
        points: &Bound<'_, PyAny>,
    ) -> PyResult<()> {
        let pts = points_from(points)?;
        self.with_frame(py, frame, |t, f| t.initialize(f, &pts))?
            .map_err(library_error)
    }

    /// Tracks one frame; returns `(centres, tracking)`: `(N, 2)` centres (a lost patch keeps
    /// its last good one) and an `(N,)` boolean array, in the order of the initial points.
    fn update<'py>(
        &mut self,
        py: Python<'py>,
        frame: &Bound<'py, PyAny>,
    ) -> PyResult<CentresAndTracking<'py>> {
        self.with_frame(py, frame, |t, f| t.update(f))?
            .map_err(library_error)?;
        let st = self.states();
        let tracking: Vec<bool> = st.iter().map(|s| s.tracking()).collect();
        Ok((
            points_to(py, st.iter().map(|s| s.centre)),
            PyArray1::from_vec(py, tracking),
        ))
    }

    /// Each patch's status: `"tracking"` or `"lost: <reason>"`.
    #[getter]
    fn status(&self) -> Vec<String> {
        self.states()
            .iter()
            .map(|s| status_text(&s.status))
            .collect()
    }

    /// Each patch's linear map `[[a00, a01], [a10, a11]]` (the identity for translation), an
    /// `(N, 2, 2)` array.
    #[getter]
    fn linear<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let rows: Vec<Vec<Vec<f64>>> = self
            .states()
            .iter()
            .map(|s| {
                vec![
                    vec![s.linear[0], s.linear[1]],
                    vec![s.linear[2], s.linear[3]],
                ]
            })
            .collect();
        if rows.is_empty() {
            return Ok(PyArray3::zeros(py, [0, 2, 2], false));
        }
        PyArray3::from_vec3(py, &rows).map_err(|e| PyValueError::new_err(e.to_string()))
    }

    /// Each patch's normalised cross-correlation with its template on the last frame.
    #[getter]
    fn ncc<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.states().iter().map(|s| s.ncc).collect())
    }

    /// The library's own time in the last call that took a frame (µs).
    #[getter]
    fn last_update_us(&self) -> f64 {
        self.last_us
    }

    fn __len__(&self) -> usize {
        self.inner.states().len()
    }

    fn __repr__(&self) -> String {
        let p = self.inner.params();
        format!(
            "PatchTracker({:?}, size={}, levels={}, {} patches, {} tracking)",
            p.warp,
            p.size,
            p.levels,
            self.inner.states().len(),
            self.inner.tracking()
        )
    }
}

/// The Python module.
#[pymodule]
fn regtrack(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyTracker>()?;
    m.add_class::<PySequence>()?;
    m.add_class::<PyCamera>()?;
    m.add_class::<PyPatchTracker>()?;
    m.add("Error", m.py().get_type::<Error>())?;
    m.add_function(wrap_pyfunction!(list_methods, m)?)?;
    m.add_function(wrap_pyfunction!(list_text, m)?)?;
    m.add_function(wrap_pyfunction!(alignment_error, m)?)?;
    m.add_function(wrap_pyfunction!(eval, m)?)?;
    m.add_function(wrap_pyfunction!(synth, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
