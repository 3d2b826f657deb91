//! `workbench bench`: run time against error for every stage, regenerated from ground truth on
//! every run. Synthetic sessions (several noise levels and sizes, PNG and JPEG) and a checkerboard
//! set are rendered with known parameters; then calibration (each corner detector), detection and
//! the joint solve at every reduction level are timed and compared with the truth. The report
//! (`report.md`, `report.json` with schema `workbench.bench/1`, and `error-vs-time.{png,svg}`)
//! gives each setting's time and error and the solve stage's time against decoding the photos,
//! both measured in the same run, and what a user waits for — `solve` on a fresh folder, stage
//! by stage, against decoding — on each session and on a many-photo session with one light per
//! photo ([`super::end_to_end`]).

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;
use workbench::detect;
use workbench::error::{Error, Result};
use workbench::fit::joint::Reduction;
use workbench::plot::{Layer, Plot, PALETTE};
use workbench::solve::{self, Options};
use workbench::synth::session::{self, Format, SessionConfig, SessionTruth};

use super::end_to_end::{self, EndToEnd};

pub(super) const SCHEMA: &str = "workbench.bench/1";

#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub out: PathBuf,
    /// A few minutes: two small sessions and a small checkerboard set.
    pub quick: bool,
    pub quiet: bool,
}

/// One measured setting.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub stage: String,
    pub data: String,
    pub setting: String,
    pub seconds: f64,
    /// The error against the truth, in `error_unit` (null where the row has none: a stage of an
    /// end-to-end solve, a detection without a light).
    pub error: Option<f64>,
    pub error_unit: String,
    /// A second error where the stage has one (the light's, degrees).
    pub light_error_deg: Option<f64>,
    /// For the solve: decoding the photos in the same run (seconds), and observations fitted.
    pub decode_s: Option<f64>,
    pub observations: Option<usize>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    pub schema: String,
    pub quick: bool,
    pub machine: String,
    pub rows: Vec<Row>,
    pub total_s: f64,
}

/// A synthetic session of the benchmark.
struct Data {
    name: String,
    size: [u32; 2],
    noise: f64,
    format: Format,
}

fn sessions(quick: bool) -> Vec<Data> {
    let d = |size: [u32; 2], noise: f64, format: Format| Data {
        name: format!(
            "{}×{} {}% {}",
            size[0],
            size[1],
            noise * 100.0,
            match format {
                Format::Png16 => "PNG",
                Format::Jpeg => "JPEG",
            }
        ),
        size,
        noise,
        format,
    };
    let mut v = vec![
        d([640, 480], 0.01, Format::Png16),
        d([640, 480], 0.05, Format::Png16),
    ];
    if !quick {
        v.push(d([1280, 960], 0.01, Format::Png16));
        v.push(d([1280, 960], 0.05, Format::Jpeg));
    }
    v
}

fn config(d: &Data) -> SessionConfig {
    let mut cam = session::default_camera();
    let s = d.size[0] as f64 / 1280.0;
    cam.fx *= s;
    cam.fy *= s;
    cam.cx = d.size[0] as f64 / 2.0 + 3.2 * s;
    cam.cy = d.size[1] as f64 / 2.0 - 1.5 * s;
    cam.image_size = d.size;
    SessionConfig {
        camera: cam,
        noise: d.noise,
        format: d.format,
        ..SessionConfig::default()
    }
}

/// The reduction settings the solve offers, every-pixel first.
pub(super) fn reductions() -> Vec<(String, Reduction)> {
    let mut v = vec![("every pixel".to_string(), Reduction::None)];
    for f in [1u32, 2, 4, 8, 16] {
        v.push((format!("{}° cells", f as f64 * 0.25), Reduction::Factor(f)));
    }
    v.push(("auto".to_string(), Reduction::Auto));
    v
}

fn machine() -> String {
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    format!("{cpu}, {cores} cores")
}

/// The file that marks a folder as made by `workbench bench` (and so deleted by its next run).
const MARK: &str = ".workbench-bench";

/// A folder the benchmark may replace: absent, or made by an earlier run (it holds [`MARK`]).
fn replaceable(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.join(MARK).is_file() {
        return Err(Error::invalid(
            dir,
            "exists and was not made by workbench bench: it would be overwritten; choose another --out or move it",
        ));
    }
    Ok(())
}

/// Make way for a folder the benchmark writes: one it made before is deleted; anything else
/// there is an error, never deleted.
fn fresh_dir(dir: &Path) -> Result<()> {
    replaceable(dir)?;
    if dir.exists() {
        std::fs::remove_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    Ok(())
}

/// Photos of the per-image-light session: 48 as DiLiGenT's (12 with `--quick`).
fn per_image_photos(quick: bool) -> usize {
    if quick {
        12
    } else {
        48
    }
}

/// The per-image-light session's name.
fn per_image_name(quick: bool) -> String {
    format!("{} photos, a light each", per_image_photos(quick))
}

fn session_dir(opts: &BenchOptions, name: &str) -> PathBuf {
    opts.out.join("sessions").join(
        name.replace(['×', ' '], "-")
            .replace('%', "pc")
            .to_lowercase(),
    )
}

fn checkerboard_dir(opts: &BenchOptions) -> PathBuf {
    opts.out.join("checkerboard")
}

fn mark_dir(dir: &Path) -> Result<()> {
    workbench::formats::output::write_bytes(&dir.join(MARK), b"made by workbench bench\n")
}

/// Run the benchmark and write its report into `opts.out`.
pub fn run(opts: &BenchOptions) -> Result<BenchReport> {
    let t0 = Instant::now();
    let data = sessions(opts.quick);
    // Every folder it will replace is checked before any work.
    for dir in data.iter().map(|d| session_dir(opts, &d.name)).chain([
        checkerboard_dir(opts),
        session_dir(opts, &per_image_name(opts.quick)),
        session_dir(opts, MEDIUM_NAME),
    ]) {
        replaceable(&dir)?;
    }
    std::fs::create_dir_all(&opts.out).map_err(|e| Error::io(&opts.out, e))?;
    let settings = reductions();
    let steps = data.len() * (3 + settings.len()) + 3;
    let pb = workbench::progress::bar(steps as u64, "bench", opts.quiet);
    let mut rows = vec![];
    #[cfg(feature = "opencv")]
    {
        rows.extend(calibration_rows(opts)?);
    }
    pb.inc(1);
    for d in &data {
        let dir = session_dir(opts, &d.name);
        fresh_dir(&dir)?;
        session::generate(&config(d), &dir, None, true)?;
        mark_dir(&dir)?;
        let truth: SessionTruth = workbench::formats::output::read_json(&dir.join("truth.json"))?;
        pb.inc(1);
        let t = Instant::now();
        let det = detect::run(&detect::Options {
            session: dir.clone(),
            out: None,
            overlays: false,
            quiet: true,
            medium_outlines: false,
        })?;
        let light = det.light_direction.map(Vector3::from);
        rows.push(Row {
            stage: "detection".into(),
            data: d.name.clone(),
            setting: "default".into(),
            seconds: t.elapsed().as_secs_f64(),
            error: light.map(|l| l.angle(&Vector3::from(truth.light_direction)).to_degrees()),
            error_unit: "light °".into(),
            light_error_deg: None,
            decode_s: None,
            observations: None,
        });
        pb.inc(1);
        for (name, reduction) in &settings {
            let mut o = Options::new(&dir);
            o.out = Some(dir.join(format!("fit-{}.json", name.replace([' ', '°', '.'], ""))));
            o.fit.reduction = *reduction;
            let f = solve::run(&o)?;
            let err = (0..3)
                .map(|c| (f.sigma0_mm[c] - truth.sigma0_mm[c]).abs() / truth.sigma0_mm[c])
                .fold(0.0, f64::max);
            rows.push(Row {
                stage: "solve".into(),
                data: d.name.clone(),
                setting: name.clone(),
                seconds: f.timings.solve_s,
                error: Some(100.0 * err),
                error_unit: "σ0 %".into(),
                light_error_deg: Some(
                    Vector3::from(f.light_direction)
                        .angle(&Vector3::from(truth.light_direction))
                        .to_degrees(),
                ),
                decode_s: Some(f.timings.decode_s),
                observations: f.reduction.as_ref().map(|r| r.chosen.observations),
            });
            pb.inc(1);
        }
        if rows.iter().all(|r| r.stage != "kernel") {
            rows.extend(kernel_rows(&dir, &d.name)?);
        }
        let e =
            end_to_end::solve_fresh(&dir, truth.sigma0_mm, Vector3::from(truth.light_direction))?;
        rows.extend(end_to_end_rows(&d.name, &e));
        pb.inc(1);
    }
    rows.extend(per_image_rows(opts, &data[0])?);
    pb.inc(1);
    rows.extend(medium_rows(opts)?);
    pb.inc(1);
    pb.finish_and_clear();
    let report = BenchReport {
        schema: SCHEMA.into(),
        quick: opts.quick,
        machine: machine(),
        rows,
        total_s: t0.elapsed().as_secs_f64(),
    };
    // One set: the figure and the Markdown, then report.json last.
    let (json, md, fig) = (
        opts.out.join("report.json"),
        opts.out.join("report.md"),
        opts.out.join("error-vs-time"),
    );
    let set = workbench::formats::output::OutputSet::begin(&[
        &json,
        &md,
        &fig.with_extension("png"),
        &fig.with_extension("svg"),
    ])?;
    workbench::formats::output::write_bytes(&md, markdown(&report).as_bytes())?;
    error_vs_time(&report).save(&fig)?;
    workbench::formats::output::write_json(&json, &report)?;
    set.commit()?;
    Ok(report)
}

/// The end-to-end solve of the many-photo session with a light per photo, on the first session's
/// camera and noise.
fn per_image_rows(opts: &BenchOptions, first: &Data) -> Result<Vec<Row>> {
    let name = per_image_name(opts.quick);
    let dir = session_dir(opts, &name);
    fresh_dir(&dir)?;
    let (sigma0, light) =
        end_to_end::per_image_session(&dir, per_image_photos(opts.quick), &config(first))?;
    mark_dir(&dir)?;
    let e = end_to_end::solve_fresh(&dir, sigma0, light)?;
    Ok(end_to_end_rows(&name, &e))
}

/// The bundled physically based session `solve --model medium` is timed on.
const MEDIUM_SOURCE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/datasets/pbr-soap");
const MEDIUM_NAME: &str = "pbr-soap, --model medium";

/// `solve --model medium` end to end on a fresh copy of the bundled soap renders (none where the
/// build's source tree is gone), its medium stage among the rows and σa, σs′ against the truth.
fn medium_rows(opts: &BenchOptions) -> Result<Vec<Row>> {
    let src = Path::new(MEDIUM_SOURCE);
    if !src.join("truth.json").is_file() {
        return Ok(vec![]);
    }
    let dir = session_dir(opts, MEDIUM_NAME);
    fresh_dir(&dir)?;
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    mark_dir(&dir)?;
    let e = end_to_end::medium_fresh(src, &dir)?;
    Ok(end_to_end_rows(MEDIUM_NAME, &e))
}

/// The stages of one end-to-end solve as rows (stage "end to end"), each with the decoding of
/// the same run; the errors on the total's row.
fn end_to_end_rows(name: &str, e: &EndToEnd) -> Vec<Row> {
    let row = |setting: &str, seconds: f64| Row {
        stage: "end to end".into(),
        data: name.into(),
        setting: setting.into(),
        seconds,
        error: None,
        error_unit: String::new(),
        light_error_deg: None,
        decode_s: Some(e.decode_s),
        observations: None,
    };
    let mut rows = vec![
        row("detection", e.detect_s),
        row("fit and light hold", e.solve_s),
        row("jackknife", e.jackknife_s),
    ];
    rows.extend(e.medium_s.map(|s| row("medium fit", s)));
    rows.push(Row {
        error: Some(e.error_pct),
        error_unit: e.error_unit.into(),
        light_error_deg: Some(e.light_error_deg),
        ..row("total", e.total_s)
    });
    rows
}

/// The solver's kernel on a session's pixels (every one, at its fit): the model, its gradient
/// and the normal equations JᵀJ, Jᵀr accumulated, on one core, with the tabulated CDRF and with
/// the closed form; the table's error is the largest difference of JᵀJ relative to its largest
/// entry. Seconds are per evaluation (the best of five).
fn kernel_rows(dir: &Path, name: &str) -> Result<Vec<Row>> {
    use workbench::fit::solver::{self, Obs};
    use workbench::model::{Model, N_PARAMS};
    let l = solve::load(&Options::new(dir))?;
    let fit: workbench::formats::fit::FitFile =
        workbench::formats::output::read_json(&dir.join("fit-auto.json"))?;
    let obs: Vec<Obs> = l
        .spheres
        .iter()
        .flat_map(|s| s.obs.iter().cloned())
        .collect();
    let mut free = [false; N_PARAMS];
    free[..11].fill(true);
    let params = fit.params();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| Error::Argument(format!("thread pool: {e}")))?;
    let run = |tabulated: bool| {
        let model = Model {
            tabulated,
            ..fit.model()
        };
        let mut best = f64::INFINITY;
        let mut ne = None;
        for _ in 0..5 {
            let t = Instant::now();
            ne = Some(pool.install(|| solver::normal_equations(model, &obs, &params, free)));
            best = best.min(t.elapsed().as_secs_f64());
        }
        (best, ne.expect("five runs").jtj)
    };
    let (t_closed, closed) = run(false);
    let (t_table, table) = run(true);
    let scale = closed.amax().max(1e-300);
    let row = |setting: &str, seconds: f64, error: f64| Row {
        stage: "kernel".into(),
        data: name.into(),
        setting: setting.into(),
        seconds,
        error: Some(error),
        error_unit: "JᵀJ rel.".into(),
        light_error_deg: None,
        decode_s: None,
        observations: Some(obs.len()),
    };
    Ok(vec![
        row("closed-form CDRF, 1 core", t_closed, 0.0),
        row(
            "tabulated CDRF, 1 core",
            t_table,
            (&table - &closed).amax() / scale,
        ),
    ])
}

#[cfg(feature = "opencv")]
fn calibration_rows(opts: &BenchOptions) -> Result<Vec<Row>> {
    use workbench::calibrate::{run as cal, DetectorChoice};
    use workbench::synth::checkerboard::{self, CheckerConfig};
    let mut cam = session::default_camera();
    cam.fx *= 0.5;
    cam.fy *= 0.5;
    cam.cx = 321.6;
    cam.cy = 239.3;
    cam.image_size = [640, 480];
    let cfg = CheckerConfig {
        camera: cam,
        views: if opts.quick { 10 } else { 15 },
        ..CheckerConfig::default()
    };
    let dir = checkerboard_dir(opts);
    fresh_dir(&dir)?;
    let out = checkerboard::generate(&cfg, &dir, true)?;
    mark_dir(&dir)?;
    let truth = out.truth.intrinsics;
    let mut rows = vec![];
    for (name, choice) in [
        ("classic", DetectorChoice::Classic),
        ("sector-based", DetectorChoice::SectorBased),
        ("auto", DetectorChoice::Auto),
    ] {
        let o = cal::Options {
            dir: dir.clone(),
            pattern: None,
            square_mm: cfg.square_mm,
            out: Some(dir.join(format!("intrinsics-{name}.json"))),
            plots: Some(dir.join(format!("plots-{name}"))),
            detector: choice,
            subpix_window: None,
            exports: vec![],
            quiet: true,
        };
        let t = Instant::now();
        let r = cal::run(
            &o,
            &workbench::calibrate::cv::OpenCvDetect,
            &workbench::calibrate::cv::OpenCv,
        )?;
        let c = &r.calibration.camera;
        rows.push(Row {
            stage: "calibration".into(),
            data: format!("640×480, {} views", cfg.views),
            setting: name.into(),
            seconds: t.elapsed().as_secs_f64(),
            error: Some(
                100.0
                    * ((c.fx - truth.fx).abs() / truth.fx).max((c.fy - truth.fy).abs() / truth.fy),
            ),
            error_unit: "fx, fy %".into(),
            light_error_deg: None,
            decode_s: None,
            observations: None,
        });
    }
    Ok(rows)
}

/// The report as Markdown: one table of every setting, then the solve against decoding.
pub fn markdown(r: &BenchReport) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "`workbench bench{}` on {} ({:.0} s in all).\n",
        if r.quick { " --quick" } else { "" },
        r.machine,
        r.total_s
    );
    s.push_str("| stage | data | setting | time (s) | error | light error (°) | observations |\n");
    s.push_str("|---|---|---|---:|---:|---:|---:|\n");
    for row in &r.rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.2} | {} | {} | {} |",
            row.stage,
            row.data,
            row.setting,
            row.seconds,
            match row.error {
                None => String::new(),
                Some(e) if row.stage == "kernel" => format!("{e:.1e} {}", row.error_unit),
                Some(e) => format!("{e:.3} {}", row.error_unit),
            },
            row.light_error_deg
                .map_or(String::new(), |e| format!("{e:.3}")),
            row.observations.map_or(String::new(), |n| n.to_string())
        );
    }
    for k in r.rows.iter().filter(|x| x.stage == "kernel") {
        if let Some(n) = k.observations {
            let _ = writeln!(
                s,
                "{}kernel, {}: {:.2} M observations/s",
                if k.setting.starts_with("closed") {
                    "\n"
                } else {
                    ""
                },
                k.setting,
                n as f64 / k.seconds / 1e6
            );
        }
    }
    s.push_str(
        "\n| data | solve (auto) / decoding | solve (every pixel) / decoding |\n|---|---:|---:|\n",
    );
    let names = sessions_of(r, "solve");
    for n in names {
        let ratio = |setting: &str| {
            r.rows
                .iter()
                .find(|x| x.stage == "solve" && x.data == n && x.setting == setting)
                .and_then(|x| x.decode_s.map(|d| x.seconds / d.max(1e-9)))
                .map_or("–".to_string(), |v| format!("{v:.1}×"))
        };
        let _ = writeln!(s, "| {n} | {} | {} |", ratio("auto"), ratio("every pixel"));
    }
    s.push_str(&end_to_end_table(r));
    s
}

/// What a user waits for: each stage of `solve` on a fresh folder against decoding its photos in
/// the same run.
fn end_to_end_table(r: &BenchReport) -> String {
    use std::fmt::Write;
    let mut s = String::from(
        "\n`solve` on a fresh folder, every default on (the pbr-soap row with `--model medium --irradiance`), each stage against decoding the photos:\n\n\
         | data | decoding (s) | detection | fit and light hold | jackknife | medium fit | total | total (s) |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for n in sessions_of(r, "end to end") {
        let get = |setting: &str| {
            r.rows
                .iter()
                .find(|x| x.stage == "end to end" && x.data == n && x.setting == setting)
        };
        // A stage of 0 s did not run (the jackknife with one radius).
        let ratio = |setting: &str| {
            get(setting)
                .filter(|x| x.seconds > 0.0)
                .and_then(|x| x.decode_s.map(|d| x.seconds / d.max(1e-9)))
                .map_or("–".to_string(), |v| format!("{v:.0}×"))
        };
        let total = get("total");
        let _ = writeln!(
            s,
            "| {n} | {} | {} | {} | {} | {} | {} | {} |",
            total
                .and_then(|x| x.decode_s)
                .map_or("–".to_string(), |d| format!("{d:.3}")),
            ratio("detection"),
            ratio("fit and light hold"),
            ratio("jackknife"),
            ratio("medium fit"),
            ratio("total"),
            total.map_or("–".to_string(), |x| format!("{:.2}", x.seconds))
        );
    }
    s
}

/// The sessions a stage ran on, in run order.
fn sessions_of<'a>(r: &'a BenchReport, stage: &str) -> Vec<&'a str> {
    let mut names: Vec<&str> = r
        .rows
        .iter()
        .filter(|x| x.stage == stage)
        .map(|x| x.data.as_str())
        .collect();
    names.dedup();
    names
}

/// σ0 error against solve time, one colour per session, each point named by its setting.
fn error_vs_time(r: &BenchReport) -> Plot {
    let mut p = Plot::new(
        "Joint solve: σ0 error against time, per reduction setting",
        "solve time (s)",
        "worst σ0 error against the truth (%)",
    );
    let names = sessions_of(r, "solve");
    let dx = 0.015
        * r.rows
            .iter()
            .filter(|x| x.stage == "solve")
            .map(|x| x.seconds)
            .fold(0.0, f64::max);
    for (k, n) in names.iter().enumerate() {
        let pts: Vec<&Row> = r
            .rows
            .iter()
            .filter(|x| x.stage == "solve" && x.data == *n)
            .collect();
        let color = PALETTE[k % PALETTE.len()];
        p.layers.push(Layer::Points {
            xy: pts
                .iter()
                .filter_map(|x| Some((x.seconds, x.error?)))
                .collect(),
            color,
            size: 5,
            label: Some(n.to_string()),
        });
        p.layers.push(Layer::Text {
            items: pts
                .iter()
                .filter_map(|x| {
                    Some((
                        (x.seconds + 2.5 * dx, x.error?),
                        x.setting.replace(" cells", ""),
                        color,
                    ))
                })
                .collect(),
            size: 12,
        });
    }
    p.size = (1100, 650);
    p
}

/// Where the report goes by default.
pub fn default_out() -> PathBuf {
    Path::new("bench-report").to_path_buf()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(stage: &str, setting: &str, seconds: f64, decode: Option<f64>) -> Row {
        Row {
            stage: stage.into(),
            data: "d".into(),
            setting: setting.into(),
            seconds,
            error: Some(0.5),
            error_unit: "σ0 %".into(),
            light_error_deg: None,
            decode_s: decode,
            observations: None,
        }
    }

    #[test]
    fn report_ratios_and_settings() {
        let r = BenchReport {
            schema: SCHEMA.into(),
            quick: true,
            machine: "m".into(),
            rows: vec![
                row("solve", "every pixel", 3.0, Some(0.5)),
                row("solve", "auto", 1.0, Some(0.5)),
            ],
            total_s: 1.0,
        };
        let md = markdown(&r);
        assert!(md.contains("| d | 2.0× | 6.0× |"), "{md}");
        let e = EndToEnd {
            decode_s: 0.25,
            detect_s: 1.0,
            solve_s: 2.5,
            jackknife_s: 0.5,
            medium_s: None,
            total_s: 4.25,
            error_pct: 1.0,
            error_unit: "σ0 %",
            light_error_deg: 0.1,
        };
        let r = BenchReport {
            rows: end_to_end_rows("e", &e),
            ..r
        };
        let md = markdown(&r);
        assert!(
            md.contains("| e | 0.250 | 4× | 10× | 2× | – | 17× | 4.25 |"),
            "{md}"
        );
        let names: Vec<String> = reductions().into_iter().map(|r| r.0).collect();
        assert_eq!(names.first().unwrap(), "every pixel");
        assert_eq!(names.last().unwrap(), "auto");
        assert!(names.contains(&"4° cells".to_string()));
    }
}
