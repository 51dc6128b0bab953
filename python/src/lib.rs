//! `fibrefit._native`: the Python bindings of fibrefit's library API (`fibrefit::api`). Arrays
//! in and out as numpy arrays; the work runs with the GIL released, in parallel (rayon). This
//! layer converts and checks shapes only: the science is in the crate. Every error is a
//! `fibrefit.FibrefitError` (a `ValueError`) carrying the message the CLI would print.

use fibrefit::api::eval::Evaluation;
use fibrefit::api::export::{self as export_api, ExportRequest};
use fibrefit::api::fit::{self as fit_api, FitOptions, FitRequest, FitRun, FitTargets, Maps};
use fibrefit::api::material::{Material as MaterialCore, Sampled};
use fibrefit::api::{DataKind, LoadFlags, Origin, Outputs};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pyo3::create_exception!(
    _native,
    FibrefitError,
    PyValueError,
    "An error of fibrefit: bad input, a failed fit or an unwritable output. The message is the one the command line prints."
);

/// The Python error (KeyboardInterrupt) a Ctrl-C raised while the crate waited on a FIFO or
/// device: the wait stopped with an error, and this is what the call raises instead.
static PENDING_SIGNAL: std::sync::Mutex<Option<PyErr>> = std::sync::Mutex::new(None);

/// Whether Ctrl-C was pressed (Python's signal handlers run; on the main thread only): the
/// crate asks while it waits on a FIFO or device, so the wait stops at once.
fn check_interrupt() -> bool {
    Python::attach(|py| match py.check_signals() {
        Ok(()) => false,
        Err(e) => {
            *PENDING_SIGNAL.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
            true
        }
    })
}

/// The CLI's rendering of an error (`error: {e:#}` without the prefix); a wait stopped by
/// Ctrl-C raises the KeyboardInterrupt instead.
fn err(e: anyhow::Error) -> PyErr {
    if let Some(signal) = PENDING_SIGNAL
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .take()
    {
        return signal;
    }
    FibrefitError::new_err(format!("{e:#}"))
}

/// An (N, width) float64 array as rows; the error names the argument and the shape.
fn rows<const W: usize>(a: &PyReadonlyArrayDyn<'_, f64>, name: &str) -> PyResult<Vec<[f64; W]>> {
    let shape = a.shape();
    if shape.len() != 2 || shape[1] != W {
        return Err(FibrefitError::new_err(format!(
            "{name}: expected an (N, {W}) array, got shape {shape:?}"
        )));
    }
    let view = a.as_array();
    Ok(view
        .outer_iter()
        .map(|r| std::array::from_fn(|i| r[i]))
        .collect())
}

fn table<'py, const W: usize>(
    py: Python<'py>,
    data: &[[f64; W]],
    cols: usize,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = data
        .iter()
        .flat_map(|r| r[..cols].iter().copied())
        .collect();
    flat.into_pyarray(py)
        .reshape([data.len(), cols])
        .map_err(|e| FibrefitError::new_err(e.to_string()))
}

/// A fitted material: the BRDF, an importance sampler and its pdf at directions in the swatch
/// frame (z the normal, x the swatch's x axis; l towards the light, v towards the viewer), with
/// the result's per-texel maps looked up at texture coordinates uv in [0, 1]^2.
#[pyclass(frozen, module = "fibrefit._native")]
struct Material {
    inner: MaterialCore,
    warnings: Vec<String>,
}

impl Material {
    fn uv(uv: Option<PyReadonlyArrayDyn<'_, f64>>) -> PyResult<Option<Vec<[f64; 2]>>> {
        uv.map(|a| rows::<2>(&a, "uv")).transpose()
    }

    /// The instance uniforms: an (N,) array.
    fn instance(instance: Option<PyReadonlyArrayDyn<'_, f64>>) -> PyResult<Option<Vec<f64>>> {
        let Some(a) = instance else {
            return Ok(None);
        };
        let shape = a.shape().to_vec();
        if shape.len() != 1 {
            return Err(FibrefitError::new_err(format!(
                "instance: expected an (N,) array, got shape {shape:?}"
            )));
        }
        Ok(Some(a.as_array().iter().copied().collect()))
    }
}

#[pymethods]
impl Material {
    /// The BRDF (1/sr), an (N, C) array (C = 3 for RGB results, 1 for grey), of the light
    /// directions `l` and view directions `v`, (N, 3) arrays of unit vectors. `instance`, an
    /// (N,) array of uniforms in [0, 1): each row's value of the instance of the material its
    /// uniform picks (see `instances`; the same uniform picks the same instance in `pdf` and
    /// `sample`, and the mean over uniforms is the material's value).
    #[pyo3(signature = (l, v, uv=None, instance=None))]
    fn eval<'py>(
        &self,
        py: Python<'py>,
        l: PyReadonlyArrayDyn<'py, f64>,
        v: PyReadonlyArrayDyn<'py, f64>,
        uv: Option<PyReadonlyArrayDyn<'py, f64>>,
        instance: Option<PyReadonlyArrayDyn<'py, f64>>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let (l, v, uv) = (rows::<3>(&l, "l")?, rows::<3>(&v, "v")?, Self::uv(uv)?);
        let instance = Self::instance(instance)?;
        let out = py
            .detach(|| {
                self.inner
                    .eval_many(&l, &v, uv.as_deref(), instance.as_deref())
            })
            .map_err(err)?;
        table(py, &out, self.inner.channels)
    }

    /// Sample light directions for the views `v` ((N, 3)) from uniforms `u` ((N, 2) in
    /// [0, 1)): returns (l (N, 3), weight (N, C) = f cos(theta_l) / pdf, pdf (N,) in 1/sr). A
    /// failed sample (below the horizon) has l = 0, weight 0, pdf 0. `instance` ((N,) uniforms
    /// in [0, 1)): each row draws from, and weighs by, the instance of the material its uniform
    /// picks (one fibre direction of a spread, one height of a histogram): many times faster
    /// where the material mixes many, its mean the same, its variance larger.
    #[pyo3(signature = (v, u, uv=None, instance=None))]
    fn sample<'py>(
        &self,
        py: Python<'py>,
        v: PyReadonlyArrayDyn<'py, f64>,
        u: PyReadonlyArrayDyn<'py, f64>,
        uv: Option<PyReadonlyArrayDyn<'py, f64>>,
        instance: Option<PyReadonlyArrayDyn<'py, f64>>,
    ) -> PyResult<(
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray2<f64>>,
        Bound<'py, PyArray1<f64>>,
    )> {
        let (v, u, uv) = (rows::<3>(&v, "v")?, rows::<2>(&u, "u")?, Self::uv(uv)?);
        let instance = Self::instance(instance)?;
        let out: Vec<Sampled> = py
            .detach(|| {
                self.inner
                    .sample_many(&v, &u, uv.as_deref(), instance.as_deref())
            })
            .map_err(err)?;
        let l: Vec<[f64; 3]> = out.iter().map(|s| s.l).collect();
        let w: Vec<[f64; 3]> = out.iter().map(|s| s.weight).collect();
        let pdf: Vec<f64> = out.iter().map(|s| s.pdf).collect();
        Ok((
            table(py, &l, 3)?,
            table(py, &w, self.inner.channels)?,
            pdf.into_pyarray(py),
        ))
    }

    /// The sampler's density (1/sr, solid angle) of the light directions `l` given the views
    /// `v`, an (N,) array; with `instance`, the density of each row's instance's sampler.
    #[pyo3(signature = (v, l, uv=None, instance=None))]
    fn pdf<'py>(
        &self,
        py: Python<'py>,
        v: PyReadonlyArrayDyn<'py, f64>,
        l: PyReadonlyArrayDyn<'py, f64>,
        uv: Option<PyReadonlyArrayDyn<'py, f64>>,
        instance: Option<PyReadonlyArrayDyn<'py, f64>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let (v, l, uv) = (rows::<3>(&v, "v")?, rows::<3>(&l, "l")?, Self::uv(uv)?);
        let instance = Self::instance(instance)?;
        let out = py
            .detach(|| {
                self.inner
                    .pdf_many(&v, &l, uv.as_deref(), instance.as_deref())
            })
            .map_err(err)?;
        Ok(out.into_pyarray(py))
    }

    /// Image `index` of a capture TOML as this material renders it, noise-free: an (H, W, C)
    /// float32 array of radiance per unit irradiance (the units of `capture_image`).
    fn render_capture<'py>(
        &self,
        py: Python<'py>,
        capture: PathBuf,
        index: usize,
    ) -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let img = py
            .detach(|| self.inner.render_capture(&capture, index))
            .map_err(err)?;
        let (w, h, c) = (img.width, img.height, img.channels);
        img.data
            .into_pyarray(py)
            .reshape([h, w, c])
            .map_err(|e| FibrefitError::new_err(e.to_string()))
    }

    /// The rung's id (e.g. "varying-topology").
    #[getter]
    fn model(&self) -> &'static str {
        self.inner.model.as_str()
    }

    /// How many instances the material mixes: a fibre-direction spread's nodes times a height
    /// histogram's heights (1: none; `eval`, `pdf` and `sample` take `instance` uniforms).
    #[getter]
    fn instances(&self) -> usize {
        self.inner.instances()
    }

    /// 3 for RGB results, 1 for grey.
    #[getter]
    fn channels(&self) -> usize {
        self.inner.channels
    }

    /// Whether per-texel maps are looked up at uv.
    #[getter]
    fn has_maps(&self) -> bool {
        self.inner.has_maps()
    }

    /// (width, height) of the maps in texels, or None.
    #[getter]
    fn maps_size(&self) -> Option<(usize, usize)> {
        self.inner.maps_size()
    }

    /// What `eval` reads at each texel of the result's per-texel maps or topology map (texel x =
    /// floor(u W), y = floor((1 - v) H), clamped; row 0 the top row), or None (no maps, lobe
    /// maps, or a topology map on another grid): a dict of `width`, `rows` and, per texel row by
    /// row, `height` (fibre radii; NaN: the spot's height distribution), `kd`, `ks`,
    /// `substrate` ((W H, 3)) and `azimuth_offset` (radians from the result's fibre azimuth).
    fn texel_fields<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(f) = self.inner.texel_fields() else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("width", f.width)?;
        d.set_item("rows", f.rows)?;
        d.set_item("height", f.height.into_pyarray(py))?;
        d.set_item("kd", table(py, &f.kd, 3)?)?;
        d.set_item("ks", table(py, &f.ks, 3)?)?;
        d.set_item("substrate", table(py, &f.substrate, 3)?)?;
        d.set_item("azimuth_offset", f.azimuth_offset.into_pyarray(py))?;
        Ok(Some(d))
    }

    /// The maps directory used, or None.
    #[getter]
    fn maps_dir(&self) -> Option<String> {
        self.inner
            .maps_dir
            .as_ref()
            .map(|d| d.display().to_string())
    }

    /// The global fibre direction psi, degrees from x towards y.
    #[getter]
    fn fibre_azimuth_deg(&self) -> f64 {
        self.inner.params.fibre_azimuth.to_degrees()
    }

    /// The file the material came from.
    #[getter]
    fn source(&self) -> String {
        self.inner.source.display().to_string()
    }

    /// Notes made while loading (parameters the rung does not use, maps not found, values the
    /// data did not determine).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.warnings.clone()
    }

    /// The result's values its data did not determine, label -> why: used as given, not
    /// measurements.
    #[getter]
    fn undetermined(&self) -> Vec<(String, String)> {
        self.inner
            .undetermined
            .iter()
            .map(|u| (u.label.clone(), u.reason.clone()))
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Material(model={:?}, channels={}, maps={}, source={:?})",
            self.inner.model.as_str(),
            self.inner.channels,
            self.inner.has_maps(),
            self.inner.source.display().to_string()
        )
    }
}

/// Load the material of a result JSON (or a parameter file): `maps` a maps directory, else the
/// one the result names (beside it).
/// `capture`: a capture TOML whose per-texel fields (tangent or azimuth map, height map) fill
/// in where the result has no maps (the capture rendered as it was fitted).
#[pyfunction]
#[pyo3(signature = (result, maps=None, capture=None))]
fn load(
    py: Python<'_>,
    result: PathBuf,
    maps: Option<PathBuf>,
    capture: Option<PathBuf>,
) -> PyResult<Material> {
    let (inner, warnings) = py
        .detach(|| {
            let (m, w) = MaterialCore::load(&result, maps.as_deref())?;
            Ok::<_, anyhow::Error>((
                match &capture {
                    Some(c) => m.with_capture(c)?,
                    None => m,
                },
                w,
            ))
        })
        .map_err(err)?;
    Ok(Material { inner, warnings })
}

/// The loading flags of `load_data`, `fit` and `score` (keyword arguments, each as the command
/// line's flag of its name; `None`: the command line's default).
#[allow(clippy::too_many_arguments)]
fn load_flags(
    stride: Option<usize>,
    fraction: Option<f64>,
    subsample_seed: Option<u64>,
    directions: Option<usize>,
    direction_seed: Option<u64>,
    max_theta: Option<f64>,
    skip_bad_rows: bool,
    small_angles_ok: bool,
    columns: Option<BTreeMap<String, String>>,
    angles: Option<String>,
) -> PyResult<LoadFlags> {
    let d = LoadFlags::default();
    Ok(LoadFlags {
        skip_bad_rows,
        small_angles_ok,
        // {ours: theirs}, as `--columns`
        columns: columns.unwrap_or_default().into_iter().collect(),
        // "deg" or "rad", as `--angles`
        angles: angles
            .map(|a| {
                a.parse()
                    .map_err(|e: String| anyhow::anyhow!("angles: {e}"))
            })
            .transpose()
            .map_err(err)?,
        stride,
        fraction,
        subsample_seed: subsample_seed.unwrap_or(d.subsample_seed),
        directions: directions.unwrap_or(d.directions),
        direction_seed: direction_seed.unwrap_or(d.direction_seed),
        max_theta_deg: max_theta.unwrap_or(d.max_theta_deg),
    })
}

/// The samples of a goniometric CSV, image capture TOML or measured-BRDF file as numpy arrays:
/// a dict with `l`, `v` ((N, 3) unit vectors, swatch frame), `theta_i`, `phi_i`, `theta_o`,
/// `phi_o` (degrees), `value` ((N, C) BRDF in 1/sr), `sigma` ((N, C), or None where the file
/// gives none), `weight`, `fibre_azimuth_deg` (NaN where the file gives none), `origin` (the
/// CSV line, or (image, x, y) of a pixel), `channels`, `kind`, `source`, `image_size`.
/// The loading flags as the command line's of the same names (`angles`: "deg" or "rad").
#[pyfunction]
#[pyo3(signature = (
    path, *, stride=None, fraction=None, subsample_seed=None, directions=None,
    direction_seed=None, max_theta=None, skip_bad_rows=false, small_angles_ok=false, columns=None, angles=None
))]
#[allow(clippy::too_many_arguments)]
fn load_data<'py>(
    py: Python<'py>,
    path: PathBuf,
    stride: Option<usize>,
    fraction: Option<f64>,
    subsample_seed: Option<u64>,
    directions: Option<usize>,
    direction_seed: Option<u64>,
    max_theta: Option<f64>,
    skip_bad_rows: bool,
    small_angles_ok: bool,
    columns: Option<BTreeMap<String, String>>,
    angles: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = load_flags(
        stride,
        fraction,
        subsample_seed,
        directions,
        direction_seed,
        max_theta,
        skip_bad_rows,
        small_angles_ok,
        columns,
        angles,
    )?
    .options()
    .map_err(err)?;
    let s = py
        .detach(|| fibrefit::api::data::load(&path, &opts))
        .map_err(err)?;
    let c = s.channels;
    let d = PyDict::new(py);
    let deg = |x: f64| x.to_degrees();
    let theta = |w: &fibrefit::api::Vec3| deg(w.z.clamp(-1.0, 1.0).acos());
    let phi = |w: &fibrefit::api::Vec3| {
        let p = deg(w.y.atan2(w.x));
        if p < 0.0 {
            p + 360.0
        } else {
            p
        }
    };
    let col = |f: &dyn Fn(&fibrefit::api::Sample) -> f64| -> Vec<f64> {
        s.samples.iter().map(f).collect()
    };
    let l: Vec<[f64; 3]> = s.samples.iter().map(|x| [x.l.x, x.l.y, x.l.z]).collect();
    let v: Vec<[f64; 3]> = s.samples.iter().map(|x| [x.v.x, x.v.y, x.v.z]).collect();
    let value: Vec<[f64; 3]> = s.samples.iter().map(|x| x.value).collect();
    d.set_item("l", table(py, &l, 3)?)?;
    d.set_item("v", table(py, &v, 3)?)?;
    d.set_item("theta_i", col(&|x| theta(&x.l)).into_pyarray(py))?;
    d.set_item("phi_i", col(&|x| phi(&x.l)).into_pyarray(py))?;
    d.set_item("theta_o", col(&|x| theta(&x.v)).into_pyarray(py))?;
    d.set_item("phi_o", col(&|x| phi(&x.v)).into_pyarray(py))?;
    d.set_item("value", table(py, &value, c)?)?;
    if s.samples.iter().any(|x| x.sigma.is_some()) {
        let sigma: Vec<[f64; 3]> = s
            .samples
            .iter()
            .map(|x| x.sigma.unwrap_or([f64::NAN; 3]))
            .collect();
        d.set_item("sigma", table(py, &sigma, c)?)?;
    } else {
        d.set_item("sigma", py.None())?;
    }
    d.set_item("weight", col(&|x| x.weight).into_pyarray(py))?;
    d.set_item(
        "fibre_azimuth_deg",
        col(&|x| x.fibre_azimuth.map_or(f64::NAN, deg)).into_pyarray(py),
    )?;
    if s.kind == DataKind::Capture {
        let o: Vec<[f64; 3]> = s
            .samples
            .iter()
            .map(|x| match x.origin {
                Origin::Pixel { image, x, y } => [image as f64, x as f64, y as f64],
                Origin::Line(n) => [n as f64, f64::NAN, f64::NAN],
            })
            .collect();
        d.set_item("origin", table(py, &o, 3)?)?;
    } else {
        let o: Vec<f64> = s
            .samples
            .iter()
            .map(|x| match x.origin {
                Origin::Line(n) => n as f64,
                Origin::Pixel { image, .. } => image as f64,
            })
            .collect();
        d.set_item("origin", o.into_pyarray(py))?;
    }
    d.set_item("channels", c)?;
    d.set_item(
        "kind",
        match s.kind {
            DataKind::Gonio => "goniometric",
            DataKind::Capture => "image capture",
            DataKind::Measured => "measured BRDF file",
        },
    )?;
    d.set_item("source", s.source.display().to_string())?;
    d.set_item("image_size", s.image_size)?;
    Ok(d)
}

/// A finished fit (see `fibrefit.fit`).
#[pyclass(unsendable, module = "fibrefit._native")]
struct FitResult {
    run: FitRun,
    request: FitRequest,
    config_file: Option<PathBuf>,
    /// Where `to_json` wrote the result (and so the maps), once it has.
    written: Option<PathBuf>,
}

#[pymethods]
impl FitResult {
    /// The result (schema fibrefit-result/1) as a JSON string, as `to_json` writes it.
    fn json(&self) -> PyResult<String> {
        serde_json::to_string_pretty(&self.run.result)
            .map_err(|e| FibrefitError::new_err(e.to_string()))
    }

    /// The fit report (lmfit's layout), as the CLI prints it.
    fn report(&self) -> String {
        self.run.report_text.clone()
    }

    /// Warnings of the fit (quality checks included).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        let mut w = self.run.warnings.clone();
        for q in &self.run.outcome.quality.warnings {
            if !w.contains(q) {
                w.push(q.clone());
            }
        }
        w
    }

    /// The fitted rung's id.
    #[getter]
    fn model(&self) -> &'static str {
        self.run.model.as_str()
    }

    /// The quality verdict: with sigmas "fits within the noise" or "does not fit within the
    /// noise"; without, judged by the floor: "within 1.2x of what the data allow" or "misses
    /// structure the data hold: ...".
    #[getter]
    fn verdict(&self) -> String {
        self.run.outcome.quality.verdict.clone()
    }

    /// The floor: what the data themselves allow on the model's held-out samples (RMS in the
    /// fit's metric); None when it was not measured (per-texel maps).
    #[getter]
    fn floor(&self) -> Option<f64> {
        self.run.outcome.quality.floor.as_ref().map(|f| f.floor)
    }

    /// The model's held-out error over the floor; None without a floor.
    #[getter]
    fn floor_ratio(&self) -> Option<f64> {
        self.run.outcome.quality.floor.as_ref().map(|f| f.ratio)
    }

    /// Where the floor's predictor is not reciprocal and the model is beyond 1.2x the floor:
    /// the same predictor made reciprocal (each
    /// training sample also at its pair with light and view swapped), what any material can
    /// reach; None where the floor is already reciprocal or was not measured.
    #[getter]
    fn reciprocal_floor(&self) -> Option<f64> {
        let f = self.run.outcome.quality.floor.as_ref()?;
        f.reciprocal.as_ref().map(|r| r.floor)
    }

    /// The smooth correction kept on the rung: (degree, held-out error with it, the rung's
    /// own, the material's: the instrument's terms aside, instrument terms per channel); None
    /// when none paid or none was tried.
    #[getter]
    fn correction(&self) -> Option<(usize, f64, f64, f64, usize)> {
        let c = self.run.outcome.correction.as_ref()?;
        Some((
            c.correction.degree,
            c.error,
            c.rung_error,
            c.material_error,
            c.correction.instrument.len(),
        ))
    }

    /// Whether per-texel maps were recovered (written by `to_json`).
    #[getter]
    fn has_maps(&self) -> bool {
        self.run.maps.is_some()
    }

    /// Write the result JSON to `path` (atomically; refused if it is an input), with the maps
    /// into the directory given to `fit(maps=...)` and a report into `report` when given.
    #[pyo3(signature = (path, report=None))]
    fn to_json(&mut self, path: PathBuf, report: Option<PathBuf>) -> PyResult<()> {
        let inputs = fit_api::inputs(&self.request, self.config_file.as_deref());
        let mut outs = Outputs::new(&inputs);
        let targets = FitTargets::reserve(&mut outs, &self.request, Some(&path), report.as_deref())
            .map_err(err)?;
        self.run.write(&mut outs, &targets).map_err(err)?;
        outs.commit().map_err(err)?;
        self.written = Some(path);
        Ok(())
    }

    /// The fitted material (`fibrefit.Material`). A maps fit's material carries its maps once
    /// `to_json` has written them.
    fn material(&self, py: Python<'_>) -> PyResult<Material> {
        let maps = match (&self.request.maps, &self.written) {
            (Maps::Into(dir), Some(_)) => Some(dir.clone()),
            _ => None,
        };
        let source = self
            .written
            .clone()
            .unwrap_or_else(|| PathBuf::from("<fit result>"));
        let value = serde_json::to_value(&self.run.result)
            .map_err(|e| FibrefitError::new_err(e.to_string()))?;
        let (inner, mut warnings) = py
            .detach(|| MaterialCore::from_result(&value, &source, maps))
            .map_err(err)?;
        if self.run.maps.is_some() && self.written.is_none() {
            warnings.push(
                "the maps are not written yet: this material has the global parameters only (call to_json first)".into(),
            );
        }
        Ok(Material { inner, warnings })
    }
}

/// Fit `data` (goniometric CSV, capture TOML or measured-BRDF file), as `fibrefit fit`, or
/// measurements held in memory: `table` (a pandas DataFrame written as CSV, read as a file is),
/// or `l`, `v` ((N, 3) unit directions), `values` ((N, C) BRDF values in 1/sr, C = 1 or 3) and
/// optionally `sigma` ((N,) or (N, C)). `config` a fit config TOML, `model` a rung id or "auto"
/// (overrides the config's), `metric` (linear, log, cosine), `fuzz` (True: `--fuzz`; False:
/// `--no-fuzz`; None: the config's), `maps` a directory for per-texel maps (captures),
/// `progress` (bars on stderr), `threads` (worker threads; None: one per core), `gltf_variant`
/// (the gltf rung's: "khronos" or "threejs", as `--gltf-variant`), `correction` (False:
/// `--no-correction`; None: the config's), the loading
/// flags as `load_data`'s (merged with the config's as the command line merges them).
#[pyfunction]
#[pyo3(signature = (
    data=None, config=None, model=None, *, table=None, l=None, v=None, values=None, sigma=None,
    metric=None, fuzz=None, maps=None, progress=false, threads=None, gltf_variant=None,
    correction=None,
    stride=None, fraction=None, subsample_seed=None, directions=None, direction_seed=None,
    max_theta=None, skip_bad_rows=false, small_angles_ok=false, columns=None, angles=None
))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    data: Option<PathBuf>,
    config: Option<PathBuf>,
    model: Option<String>,
    table: Option<String>,
    l: Option<PyReadonlyArrayDyn<'_, f64>>,
    v: Option<PyReadonlyArrayDyn<'_, f64>>,
    values: Option<PyReadonlyArrayDyn<'_, f64>>,
    sigma: Option<PyReadonlyArrayDyn<'_, f64>>,
    metric: Option<String>,
    fuzz: Option<bool>,
    maps: Option<PathBuf>,
    progress: bool,
    threads: Option<usize>,
    gltf_variant: Option<String>,
    correction: Option<bool>,
    stride: Option<usize>,
    fraction: Option<f64>,
    subsample_seed: Option<u64>,
    directions: Option<usize>,
    direction_seed: Option<u64>,
    max_theta: Option<f64>,
    skip_bad_rows: bool,
    small_angles_ok: bool,
    columns: Option<BTreeMap<String, String>>,
    angles: Option<String>,
) -> PyResult<FitResult> {
    let options = FitOptions {
        config,
        model,
        metric,
        fuzz,
        load: load_flags(
            stride,
            fraction,
            subsample_seed,
            directions,
            direction_seed,
            max_theta,
            skip_bad_rows,
            small_angles_ok,
            columns,
            angles,
        )?,
        maps: match maps {
            Some(d) => Maps::Into(d),
            None => Maps::None,
        },
        progress: fibrefit::Progress::new(!progress),
        gltf_variant,
        correction,
    };
    let source = FitSource::of(data, table, [l, v, values, sigma])?;
    let request = py
        .detach(|| match source {
            FitSource::File(path) => options.request(&path),
            FitSource::Held(held) => options.request_held(held),
        })
        .map_err(err)?;
    fit_api::check(&request).map_err(err)?;
    let req = request.clone();
    let run = py
        .detach(move || fibrefit::api::with_threads(threads, || fit_api::fit(&req)))
        .and_then(|r| r)
        .map_err(err)?;
    Ok(FitResult {
        run,
        request,
        config_file: options.config,
        written: None,
    })
}

/// What `fit` fits: a file, or measurements held in memory.
enum FitSource {
    File(PathBuf),
    Held(fibrefit::api::Held),
}

impl FitSource {
    /// The one source `fit`'s arguments name: `data`, `table`, or the arrays
    /// `[l, v, values, sigma]`.
    fn of(
        data: Option<PathBuf>,
        table: Option<String>,
        arrays: [Option<PyReadonlyArrayDyn<'_, f64>>; 4],
    ) -> PyResult<Self> {
        let [l, v, values, sigma] = arrays;
        let any_array = l.is_some() || v.is_some() || values.is_some() || sigma.is_some();
        let bad = |m: &str| Err(FibrefitError::new_err(m.to_string()));
        match (data, table, any_array) {
            (Some(p), None, false) => Ok(Self::File(p)),
            (None, Some(text), false) => Ok(Self::Held(fibrefit::api::Held::Table {
                text,
                name: "DataFrame".into(),
            })),
            (None, None, true) => {
                let (Some(l), Some(v), Some(values)) = (l, v, values) else {
                    return bad("l, v and values are needed together (sigma is optional)");
                };
                Ok(Self::Held(fibrefit::api::Held::Arrays {
                    arrays: owned_arrays(&l, &v, &values, sigma.as_ref())?,
                    name: "arrays".into(),
                }))
            }
            (None, None, false) => bad("nothing to fit: give data (a file or a DataFrame) or l, v and values (numpy arrays)"),
            _ => bad("give one source of measurements: data (a file or a DataFrame) or l, v and values (numpy arrays), not both"),
        }
    }
}

/// `fit`'s arrays as rows: `values` (N,) or (N, C); `sigma` (N,) or as `values`.
fn owned_arrays(
    l: &PyReadonlyArrayDyn<'_, f64>,
    v: &PyReadonlyArrayDyn<'_, f64>,
    values: &PyReadonlyArrayDyn<'_, f64>,
    sigma: Option<&PyReadonlyArrayDyn<'_, f64>>,
) -> PyResult<fibrefit::api::OwnedArrays> {
    let channels = match values.shape() {
        [_] => 1,
        [_, c] => *c,
        s => {
            return Err(FibrefitError::new_err(format!(
                "values: expected an (N,) or (N, C) array, got shape {s:?}"
            )))
        }
    };
    let flat = |a: &PyReadonlyArrayDyn<'_, f64>| a.as_array().iter().copied().collect::<Vec<f64>>();
    if let Some(s) = sigma {
        if s.ndim() > 2 {
            return Err(FibrefitError::new_err(format!(
                "sigma: expected an (N,) or (N, C) array, got shape {:?}",
                s.shape()
            )));
        }
    }
    Ok(fibrefit::api::OwnedArrays {
        l: rows::<3>(l, "l")?,
        v: rows::<3>(v, "v")?,
        values: flat(values),
        channels,
        sigma: sigma.map(flat),
    })
}

/// Score the result JSON `result` on `data` (goniometric CSV or capture TOML), as
/// `fibrefit score`: (the score as JSON, as `--json` prints it; the text it prints without).
/// The loading flags as `load_data`'s.
#[pyfunction]
#[pyo3(signature = (
    result, data, *, stride=None, fraction=None, subsample_seed=None, directions=None,
    direction_seed=None, max_theta=None, skip_bad_rows=false, small_angles_ok=false, columns=None, angles=None
))]
#[allow(clippy::too_many_arguments)]
fn score(
    py: Python<'_>,
    result: PathBuf,
    data: PathBuf,
    stride: Option<usize>,
    fraction: Option<f64>,
    subsample_seed: Option<u64>,
    directions: Option<usize>,
    direction_seed: Option<u64>,
    max_theta: Option<f64>,
    skip_bad_rows: bool,
    small_angles_ok: bool,
    columns: Option<BTreeMap<String, String>>,
    angles: Option<String>,
) -> PyResult<(String, String)> {
    let load = load_flags(
        stride,
        fraction,
        subsample_seed,
        directions,
        direction_seed,
        max_theta,
        skip_bad_rows,
        small_angles_ok,
        columns,
        angles,
    )?
    .options()
    .map_err(err)?;
    let s = py
        .detach(|| fibrefit::api::score::score(&result, &data, &load))
        .map_err(err)?;
    let json =
        serde_json::to_string_pretty(&s).map_err(|e| FibrefitError::new_err(e.to_string()))?;
    Ok((json, fibrefit::api::score_text(&s)))
}

/// The BRDF and intensity of the parameter file (or result JSON) `params` at the queries of
/// the CSV `queries`, as `fibrefit eval`: (brdf, intensity), (N, C) arrays in 1/sr (intensity
/// f cos theta_i), C = 3 for RGB parameters or albedo columns, else 1. `model` overrides the
/// file's rung; `progress`: the bar and the parameter file's warnings on stderr.
#[pyfunction]
#[pyo3(signature = (params, queries, model=None, *, progress=false))]
fn eval<'py>(
    py: Python<'py>,
    params: PathBuf,
    queries: PathBuf,
    model: Option<String>,
    progress: bool,
) -> PyResult<(Bound<'py, PyArray2<f64>>, Bound<'py, PyArray2<f64>>)> {
    let progress = fibrefit::Progress::new(!progress);
    let out = py
        .detach(|| Evaluation::load(&params, model.as_deref(), &queries, &progress)?.run(&progress))
        .map_err(err)?;
    let brdf: Vec<[f64; 3]> = out.values.iter().map(|(b, _)| *b).collect();
    let intensity: Vec<[f64; 3]> = out.values.iter().map(|(_, i)| *i).collect();
    Ok((
        table(py, &brdf, out.channels)?,
        table(py, &intensity, out.channels)?,
    ))
}

/// `fibrefit board`: the printable calibration board written into `out` (`board.png`,
/// `board.toml`). Returns the paths written.
#[pyfunction]
#[pyo3(signature = (out, *, paper="a4", window_mm=60.0, dpi=300, patch_reflectance=0.5))]
fn board(
    py: Python<'_>,
    out: PathBuf,
    paper: &str,
    window_mm: f64,
    dpi: u32,
    patch_reflectance: f64,
) -> PyResult<Vec<PathBuf>> {
    let req = fibrefit::api::board::BoardRequest {
        paper: paper.to_string(),
        window_mm,
        dpi,
        patch_reflectance,
    };
    let o = py
        .detach(|| fibrefit::api::board::board(&req, &out))
        .map_err(err)?;
    Ok(o.files)
}

/// `fibrefit calibrate`: photos of a swatch on the board `board` (board.toml) made into a
/// capture in `out`. Returns (the capture file's path, the report's text).
#[pyfunction]
#[pyo3(signature = (board, photos, out, *, flash_offset_mm=(10.0, 0.0, 0.0), texels=None, px_per_mm=None, intrinsics=None, lights=None, encoding="srgb", progress=false))]
#[allow(clippy::too_many_arguments)]
fn calibrate(
    py: Python<'_>,
    board: PathBuf,
    photos: Vec<PathBuf>,
    out: PathBuf,
    flash_offset_mm: (f64, f64, f64),
    texels: Option<(usize, usize)>,
    px_per_mm: Option<f64>,
    intrinsics: Option<PathBuf>,
    lights: Option<PathBuf>,
    encoding: &str,
    progress: bool,
) -> PyResult<(PathBuf, String)> {
    if texels.is_some() && px_per_mm.is_some() {
        return Err(FibrefitError::new_err(
            "give texels or px_per_mm, not both".to_string(),
        ));
    }
    let encoding = match encoding {
        "srgb" => fibrefit::api::calibrate::Encoding::Srgb,
        "linear" => fibrefit::api::calibrate::Encoding::Linear,
        other => {
            return Err(FibrefitError::new_err(format!(
                "encoding = {other:?}: expected \"srgb\" or \"linear\""
            )))
        }
    };
    let texels = texels.unwrap_or((128, 128));
    let req = fibrefit::api::calibrate::CalibrateRequest {
        flash_offset_mm: [flash_offset_mm.0, flash_offset_mm.1, flash_offset_mm.2],
        texels: [texels.0, texels.1],
        px_per_mm,
        intrinsics,
        lights,
        encoding,
        ..fibrefit::api::calibrate::CalibrateRequest::new(board, photos)
    };
    let o = py
        .detach(|| {
            fibrefit::api::calibrate::calibrate(&req, &out, &fibrefit::Progress::new(!progress))
        })
        .map_err(err)?;
    Ok((o.capture, o.report))
}

/// `fibrefit view`: the viewer page of `result` (a fitted result JSON or a parameter file)
/// written to `out` (default: `result` with the extension `.html`), compared with `data` (default:
/// the data file the result names, beside it). Returns the path written.
#[pyfunction]
#[pyo3(signature = (result, out=None, data=None, *, progress=false))]
fn view(
    py: Python<'_>,
    result: PathBuf,
    out: Option<PathBuf>,
    data: Option<PathBuf>,
    progress: bool,
) -> PyResult<PathBuf> {
    let out = out.unwrap_or_else(|| result.with_extension("html"));
    let req = fibrefit::api::view::ViewRequest {
        result,
        data,
        progress: fibrefit::Progress::new(!progress),
    };
    py.detach(|| fibrefit::api::view::write(&req, &out))
        .map_err(err)?;
    Ok(out)
}

/// A material's textures as a dict: input -> {`file` (its name beside the material file),
/// `path` (where it was written, or None), `pixels` ((height, width, 3) float32, rows from the
/// top)}.
fn textures_dict<'py>(
    py: Python<'py>,
    t: &fibrefit::api::export::MaterialTextures,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for tex in &t.textures {
        let e = PyDict::new(py);
        let file = t.file_name(tex);
        e.set_item("path", t.dir.as_ref().map(|dir| dir.join(&file)))?;
        e.set_item("file", file)?;
        let px =
            numpy::PyArray1::from_vec(py, tex.rgb.clone()).reshape([tex.height, tex.width, 3])?;
        e.set_item("pixels", px)?;
        d.set_item(tex.input, e)?;
    }
    Ok(d)
}

/// An export of `result` asking only for a renderer's material: the Blender script (`blender`:
/// its name) or the OpenPBR material (`openpbr`: its name and the flag errors name).
fn material_request(
    result: PathBuf,
    blender: Option<String>,
    openpbr: Option<(String, &'static str)>,
    progress: bool,
) -> ExportRequest {
    ExportRequest {
        result,
        model: None,
        shader: None,
        check: false,
        gltf: false,
        object: "swatch".to_string(),
        blender,
        openpbr,
        progress: fibrefit::Progress::new(!progress),
    }
}

/// The Blender script `fibrefit export RESULT --blender FILE.py --name NAME` writes, in memory:
/// a dict with `script` (the Python source), `name` (the material's name: `name`, or the
/// result's file stem), `inputs` (the Principled BSDF's inputs it sets, by Blender's names),
/// `fibre_azimuth_deg` and `error_text` (the fit's error against its data). `result` must be a
/// `principled` fit without the fuzz layer or a fit that recorded the `principled` material
/// (`renderer_materials`; anything else raises, as the CLI refuses it).
///
/// `out` (a `.py` path): also write the script there, a maps fit's textures beside it (as the
/// command line writes them, through its checked writer), and return that script.
#[pyfunction]
#[pyo3(signature = (result, name=None, out=None, *, progress=false))]
fn blender_script<'py>(
    py: Python<'py>,
    result: PathBuf,
    name: Option<String>,
    out: Option<PathBuf>,
    progress: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let name = name.unwrap_or_default();
    let req = material_request(result, Some(name), None, progress);
    let built = py.detach(|| export_api::export(&req)).map_err(err)?;
    let (mut m, mut script, error) = built
        .blender
        .ok_or_else(|| FibrefitError::new_err("no Blender material was built"))?;
    if let Some(out) = &out {
        m = py
            .detach(|| -> anyhow::Result<_> {
                if !out
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("py"))
                {
                    anyhow::bail!("out {}: expected a .py file name", out.display());
                }
                let mut outs = fibrefit::api::Outputs::new(&export_api::inputs(&req));
                let id = outs.file(out, "out")?;
                let m = export_api::stage_blender(&mut outs, id, &m, (out, "out"), &mut vec![])?;
                outs.commit()?;
                Ok(m)
            })
            .map_err(err)?;
        script = m.script();
    }
    let d = PyDict::new(py);
    d.set_item("script", script)?;
    d.set_item("textures", textures_dict(py, &m.textures)?)?;
    d.set_item("name", &m.name)?;
    let inputs = PyDict::new(py);
    for (k, v) in m.inputs() {
        if v.len() == 1 {
            inputs.set_item(k, v[0])?;
        } else {
            inputs.set_item(k, v)?;
        }
    }
    d.set_item("inputs", inputs)?;
    d.set_item("fibre_azimuth_deg", m.fibre_azimuth_deg)?;
    d.set_item("error_text", error.text())?;
    Ok(d)
}

/// The OpenPBR material `fibrefit export RESULT --materialx FILE.mtlx --usd FILE.usda --name
/// NAME` writes, in memory: a dict with `document` (the MaterialX document), `usda` (the USD
/// stage), `name` (the material's name, made a valid MaterialX name), `inputs` (the OpenPBR
/// Surface inputs it sets, by OpenPBR's names: floats, colours as lists),
/// `tangent_rotation_deg` (the `rotate3d` amount of the UV tangent), `fibre_azimuth_deg`,
/// `preview_roughness` (the UsdPreviewSurface fallback's) and `error_text` (the fit's error
/// against its data). `result` must be an `openpbr` fit without the fuzz layer or a fit that
/// recorded the `openpbr` material (`renderer_materials`; anything else raises, as the CLI
/// refuses it).
///
/// `materialx` (a `.mtlx` path), `usd` (a `.usda` path): also write the document or the stage
/// there, a maps fit's textures beside each (as the command line writes them), and return
/// those texts.
#[pyfunction]
#[pyo3(signature = (result, name=None, materialx=None, usd=None, *, progress=false))]
fn openpbr_material<'py>(
    py: Python<'py>,
    result: PathBuf,
    name: Option<String>,
    materialx: Option<PathBuf>,
    usd: Option<PathBuf>,
    progress: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let flag = match (&materialx, &usd) {
        (None, Some(_)) => "--usd",
        _ => "--materialx",
    };
    let name = (name.unwrap_or_default(), flag);
    let req = material_request(result, None, Some(name), progress);
    let built = py.detach(|| export_api::export(&req)).map_err(err)?;
    let (m, error) = built
        .openpbr
        .ok_or_else(|| FibrefitError::new_err("no OpenPBR material was built"))?;
    // the materials the document and the stage are written from (textures named after each)
    let (mut mx, mut us) = (m.clone(), m.clone());
    if materialx.is_some() || usd.is_some() {
        (mx, us) = py
            .detach(|| -> anyhow::Result<_> {
                let mut outs = fibrefit::api::Outputs::new(&export_api::inputs(&req));
                let mut ids = vec![];
                for (path, ext, flag, is_usd) in [
                    (&materialx, "mtlx", "materialx", false),
                    (&usd, "usda", "usd", true),
                ] {
                    if let Some(p) = path {
                        if !p.extension().is_some_and(|e| e.eq_ignore_ascii_case(ext)) {
                            anyhow::bail!("{flag} {}: expected a .{ext} file name", p.display());
                        }
                        ids.push((outs.file(p, flag)?, p, flag, is_usd));
                    }
                }
                let (mut mx, mut us) = (m.clone(), m.clone());
                let mut shared = vec![];
                for (id, p, flag, is_usd) in ids {
                    let to = (p.as_path(), flag, is_usd);
                    let staged = export_api::stage_openpbr(&mut outs, id, &m, to, &mut shared)?;
                    *(if is_usd { &mut us } else { &mut mx }) = staged;
                }
                outs.commit()?;
                Ok((mx, us))
            })
            .map_err(err)?;
    }
    let d = PyDict::new(py);
    d.set_item("document", mx.document())?;
    d.set_item("usda", us.usda())?;
    let written = if usd.is_some() { &us } else { &mx };
    d.set_item("textures", textures_dict(py, &written.textures)?)?;
    d.set_item("name", &m.name)?;
    let inputs = PyDict::new(py);
    for (k, v) in m.inputs() {
        match v {
            export_api::OpenPbrValue::Float(x) => inputs.set_item(k, x)?,
            export_api::OpenPbrValue::Color(c) => inputs.set_item(k, c.to_vec())?,
        }
    }
    d.set_item("inputs", inputs)?;
    d.set_item("tangent_rotation_deg", m.tangent_rotation_deg())?;
    d.set_item("fibre_azimuth_deg", m.fibre_azimuth_deg)?;
    d.set_item("preview_roughness", m.preview_roughness())?;
    d.set_item("error_text", error.text())?;
    Ok(d)
}

/// The fitted model of the result JSON (or parameter file) `result` as `fibrefit export`
/// builds it, in memory: a dict with `model`, `shader` (the source in `shader`'s language:
/// wgsl, glsl, hlsl or msl; or None), `glb` (bytes of the GLB preview on `object` when `gltf`;
/// or None), `gltf_material` (the fitted glTF material and its errors; or None) and `textures`
/// (what the GLB's textures were made from; or None). `check`: run the shader on the GPU
/// driver first (this package is built without one: refused). `model` overrides the file's
/// rung; `progress`: notes and warnings on stderr.
#[pyfunction]
#[pyo3(signature = (result, shader=None, gltf=false, object="swatch", check=false, model=None, *, progress=false))]
#[allow(clippy::too_many_arguments)]
fn export<'py>(
    py: Python<'py>,
    result: PathBuf,
    shader: Option<String>,
    gltf: bool,
    object: &str,
    check: bool,
    model: Option<String>,
    progress: bool,
) -> PyResult<Bound<'py, PyDict>> {
    if shader.is_none() && !gltf {
        return Err(FibrefitError::new_err(
            "nothing to export: give shader=LANG and/or gltf=True",
        ));
    }
    if check && shader.is_none() {
        return Err(FibrefitError::new_err(
            "check=True checks the exported shader: give shader=LANG",
        ));
    }
    let req = ExportRequest {
        result,
        model,
        shader: shader
            .as_deref()
            .map(|s| {
                s.parse()
                    .map_err(|e: String| FibrefitError::new_err(format!("shader: {e}")))
            })
            .transpose()?,
        check,
        gltf,
        object: object.to_string(),
        blender: None,
        openpbr: None,
        progress: fibrefit::Progress::new(!progress),
    };
    let out = py.detach(|| export_api::export(&req)).map_err(err)?;
    let d = PyDict::new(py);
    d.set_item("model", out.model.as_str())?;
    d.set_item("shader", out.shader)?;
    match out.glb {
        Some((
            bytes,
            export_api::GltfRoute::Fitted {
                values,
                error,
                recorded_by,
            },
        )) => {
            d.set_item("glb", PyBytes::new(py, &bytes))?;
            let g = PyDict::new(py);
            let s = &values.shape;
            // "recorded": the gltf material another rung's fit recorded, fitted to its data
            g.set_item(
                "route",
                if recorded_by.is_some() {
                    "recorded"
                } else {
                    "fitted"
                },
            )?;
            g.set_item("recorded_by", recorded_by.map(|m| m.to_string()))?;
            g.set_item("base_color", values.base_color.to_vec())?;
            g.set_item("metallic", s.metallic)?;
            g.set_item("roughness", s.roughness)?;
            g.set_item("anisotropy_strength", s.anisotropy)?;
            g.set_item("anisotropy_rotation_rad", values.anisotropy_rotation)?;
            g.set_item("specular_factor", s.specular)?;
            g.set_item("ior", s.ior)?;
            if s.sheen > 0.0 {
                let sh = PyDict::new(py);
                sh.set_item("colour", s.sheen)?;
                sh.set_item("roughness", s.sheen_roughness)?;
                g.set_item("sheen", sh)?;
            } else {
                g.set_item("sheen", py.None())?;
            }
            g.set_item("relative_rms_error_against_data", error.relative_rmse)?;
            g.set_item("heldout_error", error.heldout_error)?;
            g.set_item("error_text", error.text())?;
            d.set_item("gltf_material", g)?;
        }
        Some((
            bytes,
            export_api::GltfRoute::Converted {
                material: fitted,
                why,
                source_error,
            },
        )) => {
            d.set_item("glb", PyBytes::new(py, &bytes))?;
            let m = &fitted.material;
            let g = PyDict::new(py);
            g.set_item("route", "converted")?;
            g.set_item("why_converted", why)?;
            g.set_item("source_error_text", source_error.text())?;
            g.set_item("base_color", m.base_color.to_vec())?;
            g.set_item("roughness", m.roughness)?;
            g.set_item("anisotropy_strength", m.anisotropy_strength)?;
            g.set_item("anisotropy_rotation_rad", m.anisotropy_rotation)?;
            g.set_item("ior", m.ior)?;
            match m.sheen {
                Some(s) => {
                    let sh = PyDict::new(py);
                    sh.set_item("colour", s.colour)?;
                    sh.set_item("roughness", s.roughness)?;
                    g.set_item("sheen", sh)?;
                }
                None => g.set_item("sheen", py.None())?,
            }
            g.set_item("rms_error", fitted.rms_error)?;
            g.set_item("relative_rms_error", fitted.relative_rms_error)?;
            g.set_item(
                "isotropic_relative_rms_error",
                fitted.isotropic_relative_rms_error,
            )?;
            g.set_item(
                "without_sheen_relative_rms_error",
                fitted.without_sheen_relative_rms_error,
            )?;
            g.set_item(
                "with_sheen_relative_rms_error",
                fitted.with_sheen_relative_rms_error,
            )?;
            g.set_item("directions", fitted.directions)?;
            d.set_item("gltf_material", g)?;
        }
        None => {
            d.set_item("glb", py.None())?;
            d.set_item("gltf_material", py.None())?;
        }
    }
    match out.textures {
        Some(t) => {
            let td = PyDict::new(py);
            td.set_item("directory", path_str(&t.directory))?;
            td.set_item("width", t.width)?;
            td.set_item("height", t.height)?;
            td.set_item("names", t.names)?;
            d.set_item("textures", td)?;
        }
        None => d.set_item("textures", py.None())?,
    }
    // the values the result's data did not determine, which the exports use as given
    let und = PyDict::new(py);
    for u in &out.undetermined {
        und.set_item(u.label.as_str(), u.reason.as_str())?;
    }
    d.set_item("undetermined", und)?;
    Ok(d)
}

/// The crate's version.
#[pyfunction]
fn version() -> &'static str {
    env!("CARGO_PKG_VERSION")
}

fn path_str(p: &Path) -> String {
    p.display().to_string()
}

/// The geometry of an image capture TOML as plain data (for `fibrefit.mitsuba.capture_scene`):
/// a JSON string (see `fibrefit::api::data::capture_geometry_json`).
#[pyfunction]
fn capture_geometry(py: Python<'_>, capture: PathBuf) -> PyResult<String> {
    py.detach(|| fibrefit::api::data::capture_geometry_json(&capture))
        .map_err(|e| err(e.context(path_str(&capture))))
}

/// Image `index` of a capture TOML as a renderer's scene (for
/// `fibrefit.mitsuba.capture_scene`): a JSON string (see `fibrefit::api::capture::ImageScene`).
#[pyfunction]
fn image_scene(py: Python<'_>, capture: PathBuf, index: usize) -> PyResult<String> {
    py.detach(|| fibrefit::api::capture::image_scene_json(&capture, index))
        .map_err(err)
}

/// Image `index` of a capture as the fit reads it, times its exposure: an (H, W, C) float32
/// array of radiance per unit irradiance (row 0 at the top), and an (H, W) bool array of
/// saturated pixels.
#[pyfunction]
fn capture_image<'py>(
    py: Python<'py>,
    capture: PathBuf,
    index: usize,
) -> PyResult<(Bound<'py, numpy::PyArray3<f32>>, Bound<'py, PyArray2<bool>>)> {
    let img = py
        .detach(|| fibrefit::api::data::capture_image(&capture, index))
        .map_err(err)?;
    let (w, h, c) = (img.width, img.height, img.channels);
    let data = img
        .data
        .into_pyarray(py)
        .reshape([h, w, c])
        .map_err(|e| FibrefitError::new_err(e.to_string()))?;
    let sat = img
        .saturated
        .into_pyarray(py)
        .reshape([h, w])
        .map_err(|e| FibrefitError::new_err(e.to_string()))?;
    Ok((data, sat))
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    fibrefit::api::data::set_interrupt_check(check_interrupt);
    m.add("FibrefitError", m.py().get_type::<FibrefitError>())?;
    m.add_class::<Material>()?;
    m.add_class::<FitResult>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(load_data, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(score, m)?)?;
    m.add_function(wrap_pyfunction!(eval, m)?)?;
    m.add_function(wrap_pyfunction!(export, m)?)?;
    m.add_function(wrap_pyfunction!(blender_script, m)?)?;
    m.add_function(wrap_pyfunction!(openpbr_material, m)?)?;
    m.add_function(wrap_pyfunction!(view, m)?)?;
    m.add_function(wrap_pyfunction!(board, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(image_scene, m)?)?;
    m.add_function(wrap_pyfunction!(version, m)?)?;
    m.add_function(wrap_pyfunction!(capture_geometry, m)?)?;
    m.add_function(wrap_pyfunction!(capture_image, m)?)?;
    Ok(())
}
