//! Log-log plots of error against frame time (plotters, drawn into an RGB buffer and written as
//! PNG by `image`).
//!
//! Text needs a TrueType font: `$BSPVT_FONT`, else the first of a few common system fonts
//! (Debian: `fonts-dejavu-core`). Without one the plots are skipped and the report says why.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Context, Result, anyhow, bail};
use plotters::prelude::*;
use plotters::style::FontStyle;

use super::env::EnvReport;
use super::scene::{Entry, SceneReport};

const WIDTH: u32 = 900;
const HEIGHT: u32 = 600;

/// Where a sans-serif TrueType font is looked for when `$BSPVT_FONT` is not set.
const FONT_CANDIDATES: [&str; 4] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/truetype/freefont/FreeSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
];

/// Registers the font once per process; the error says which files were tried.
pub(crate) fn ensure_font() -> Result<()> {
    static FONT: OnceLock<Result<PathBuf, String>> = OnceLock::new();
    let r = FONT.get_or_init(|| {
        let candidates: Vec<PathBuf> = match std::env::var_os("BSPVT_FONT") {
            Some(p) => vec![PathBuf::from(p)],
            None => FONT_CANDIDATES.iter().map(PathBuf::from).collect(),
        };
        for p in &candidates {
            if let Ok(bytes) = std::fs::read(p) {
                // plotters keeps fonts for the process's lifetime ('static).
                let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
                if plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok() {
                    return Ok(p.clone());
                }
            }
        }
        Err(format!(
            "no TrueType font found (tried {}); install fonts-dejavu-core or set BSPVT_FONT",
            candidates
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ))
    });
    r.as_ref().map(|_| ()).map_err(|e| anyhow!("{e}"))
}

/// Which error a plot shows.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Metric {
    Rmse,
    Flip,
}

impl Metric {
    fn name(self) -> &'static str {
        match self {
            Metric::Rmse => "RMSE",
            Metric::Flip => "mean FLIP",
        }
    }
    fn of(self, e: &Entry) -> f64 {
        match self {
            Metric::Rmse => e.metrics.rmse,
            Metric::Flip => e.metrics.flip,
        }
    }
    fn file(self) -> &'static str {
        match self {
            Metric::Rmse => "rmse-vs-time.png",
            Metric::Flip => "flip-vs-time.png",
        }
    }
}

/// A series: entries of one method (lines join increasing sample counts).
struct Series<'a> {
    name: String,
    colour: RGBColor,
    line: bool,
    points: Vec<&'a Entry>,
}

fn series(s: &SceneReport) -> Vec<Series<'_>> {
    let of = |m: &str| -> Vec<&Entry> {
        let mut v: Vec<&Entry> = s.entries.iter().filter(|e| e.method == m).collect();
        v.sort_by_key(|e| e.spp.unwrap_or(0));
        v
    };
    let bspvt = |mode: &str| -> Vec<&Entry> {
        s.entries
            .iter()
            .filter(|e| e.method == "bspvt" && e.label().ends_with(mode))
            .collect()
    };
    let mut out = vec![
        Series {
            name: "BSPVT per pixel".into(),
            colour: RGBColor(200, 30, 30),
            line: false,
            points: bspvt("pixel"),
        },
        Series {
            name: "BSPVT per vertex".into(),
            colour: RGBColor(240, 130, 40),
            line: false,
            points: bspvt("vertex"),
        },
        Series {
            name: "Monte Carlo".into(),
            colour: RGBColor(40, 80, 200),
            line: true,
            points: of("mc"),
        },
        Series {
            name: "ratio estimator".into(),
            colour: RGBColor(30, 150, 60),
            line: true,
            points: of("ratio"),
        },
        Series {
            name: "ratio + denoise".into(),
            colour: RGBColor(120, 60, 170),
            line: true,
            points: of("ratio-denoised"),
        },
    ];
    for (m, colour) in [
        ("ltc", RGBColor(90, 90, 90)),
        ("ltc-exact", RGBColor(0, 160, 160)),
        ("rt-penumbra", RGBColor(180, 140, 0)),
        ("rt-hard", RGBColor(120, 100, 40)),
        ("pcf", RGBColor(150, 100, 140)),
        ("vsm", RGBColor(60, 120, 160)),
        ("pcss", RGBColor(200, 90, 150)),
    ] {
        out.push(Series {
            name: if m == "ltc" {
                "unshadowed LTC".into()
            } else {
                m.into()
            },
            colour,
            line: false,
            points: of(m),
        });
    }
    out.retain(|s| !s.points.is_empty());
    out
}

/// Writes the scene's plot of `metric` against ms per frame into `dir`; returns its path.
pub(crate) fn plot(s: &SceneReport, metric: Metric, dir: &Path) -> Result<PathBuf> {
    let floor = match metric {
        Metric::Rmse => Some(s.ground_truth.rmse_floor),
        Metric::Flip => None,
    };
    let title = format!("{}: {} vs time per frame", s.name, metric.name());
    draw(&title, &series(s), metric, floor, &dir.join(metric.file()))
}

/// The environment-lighting plot (RMSE) of a scene, `dir/env/rmse-vs-time.png`.
pub(crate) fn env_plot(s: &SceneReport, env: &EnvReport, dir: &Path) -> Result<PathBuf> {
    let of = |m: &str| -> Vec<&Entry> {
        let mut v: Vec<&Entry> = env.entries.iter().filter(|e| e.method == m).collect();
        v.sort_by_key(|e| {
            (
                e.lobes.unwrap_or(0),
                e.pieces.unwrap_or(0),
                e.spp.unwrap_or(0),
            )
        });
        v
    };
    let series = vec![
        Series {
            name: "SG, screen-space SSDF".into(),
            colour: RGBColor(200, 30, 30),
            line: false,
            points: of("sg-screen"),
        },
        Series {
            name: "SG, exact SSDF".into(),
            colour: RGBColor(240, 130, 40),
            line: false,
            points: of("sg-exact"),
        },
        Series {
            name: "SG, unshadowed".into(),
            colour: RGBColor(90, 90, 90),
            line: false,
            points: of("sg-unshadowed"),
        },
        Series {
            name: "Monte Carlo".into(),
            colour: RGBColor(40, 80, 200),
            line: true,
            points: of("mc-env"),
        },
        Series {
            name: "BSPVT sky, per vertex (k = 1, 2, 4, …)".into(),
            colour: RGBColor(20, 150, 60),
            line: true,
            points: of("bspvt-env"),
        },
        Series {
            name: format!(
                "BSPVT sky in {} cells, per vertex, the map turning",
                2 * bspvt_client::sky_cells::DEFAULT_BANDS.pow(2)
            ),
            colour: RGBColor(20, 190, 190),
            line: false,
            points: of("bspvt-env-cells"),
        },
        Series {
            name: "BSPVT sky, per pixel (k = 1, 2, 4, …)".into(),
            colour: RGBColor(120, 40, 160),
            line: true,
            points: of("bspvt-env-pixel"),
        },
    ];
    let title = format!(
        "{} under the environment map: RMSE vs time per frame",
        s.name
    );
    let dir = dir.join("env");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    draw(
        &title,
        &series,
        Metric::Rmse,
        Some(env.gt_rmse_floor),
        &dir.join(Metric::Rmse.file()),
    )
}

/// Draws `all` (error against ms per frame, log-log) to `path`, with the ground truth's own
/// error as a horizontal line when given.
fn draw(
    title: &str,
    all: &[Series],
    metric: Metric,
    floor: Option<f64>,
    path: &Path,
) -> Result<PathBuf> {
    ensure_font()?;
    let floor = floor.filter(|f| *f > 0.0 && f.is_finite());
    let pts: Vec<(f64, f64)> = all
        .iter()
        .flat_map(|se| se.points.iter().map(|e| (e.ms_per_frame, metric.of(e))))
        .filter(|(t, e)| *t > 0.0 && *e > 0.0 && t.is_finite() && e.is_finite())
        .collect();
    if pts.is_empty() {
        bail!("nothing to plot");
    }
    let range = |v: &mut dyn Iterator<Item = f64>| {
        let (lo, hi) = v.fold((f64::MAX, f64::MIN), |(a, b), x| (a.min(x), b.max(x)));
        (lo / 1.5)..(hi * 1.5)
    };
    let xr = range(&mut pts.iter().map(|p| p.0));
    let yr = range(&mut pts.iter().map(|p| p.1).chain(floor));
    let mut buf = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (WIDTH, HEIGHT)).into_drawing_area();
        let err = |e: &dyn std::fmt::Display| anyhow!("plot: {e}");
        root.fill(&WHITE).map_err(|e| err(&e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d(xr.clone().log_scale(), yr.log_scale())
            .map_err(|e| err(&e))?;
        chart
            .configure_mesh()
            .x_desc("ms per frame (log)")
            .y_desc(format!("{} vs ground truth (log)", metric.name()))
            .y_label_formatter(&|y| format!("{y:.1e}"))
            .label_style(("sans-serif", 14))
            .draw()
            .map_err(|e| err(&e))?;
        for se in all {
            let p: Vec<(f64, f64)> = se
                .points
                .iter()
                .map(|e| (e.ms_per_frame, metric.of(e)))
                .filter(|(t, e)| *t > 0.0 && *e > 0.0 && t.is_finite() && e.is_finite())
                .collect();
            let colour = se.colour;
            if se.line {
                chart
                    .draw_series(LineSeries::new(p.clone(), colour.stroke_width(2)))
                    .map_err(|e| err(&e))?;
            }
            chart
                .draw_series(p.iter().map(|&q| Circle::new(q, 4, colour.filled())))
                .map_err(|e| err(&e))?
                .label(se.name.clone())
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, colour.filled()));
        }
        {
            // The ground truth's own RMSE: no method can measure below it.
            if let Some(floor) = floor {
                let grey = RGBColor(150, 150, 150);
                chart
                    .draw_series(LineSeries::new(
                        [(xr.start, floor), (xr.end, floor)],
                        grey.stroke_width(1),
                    ))
                    .map_err(|e| err(&e))?
                    .label("ground-truth noise")
                    .legend(move |(x, y)| {
                        PathElement::new([(x, y), (x + 16, y)], grey.stroke_width(1))
                    });
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| err(&e))?;
        root.present().map_err(|e| err(&e))?;
    }
    image::RgbImage::from_raw(WIDTH, HEIGHT, buf)
        .context("plot buffer size")?
        .save(path)
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path.to_path_buf())
}

/// Both plots of a scene; the error (e.g. no font) when they cannot be drawn.
pub(crate) fn plots(s: &SceneReport, dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out: Vec<PathBuf> = [Metric::Rmse, Metric::Flip]
        .iter()
        .map(|&m| plot(s, m, dir))
        .collect::<Result<_>>()?;
    if let Some(env) = &s.env {
        out.push(env_plot(s, env, dir)?);
    }
    Ok(out)
}
