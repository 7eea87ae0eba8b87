//! A two-panel PNG figure comparing stabilization modes, in the style of the
//! paper's Figure 2.
//!
//! * Top panel: angular speed (deg/s) against time (s): the speed of the
//!   estimated camera orientation (drawn once, from the first series) and the
//!   speed of each mode's stabilized view (the `"none"` mode is skipped, its
//!   view is the camera). Saccades are marked as short vertical ticks along the
//!   top edge of the panel, one row per mode that has any.
//! * Bottom panel: RMS normal flow of the output (px/frame) per frame, one line
//!   per mode.
//!
//! The picture is 1600x1000 px. It is rendered into memory with `plotters`'
//! bitmap backend, encoded as PNG with the `image` crate and written
//! atomically (a temporary file in the target directory, renamed onto the
//! path), so a failed run never leaves a partial file behind.
//!
//! Text needs a TrueType font, loaded at run time from the first of
//! [`FONT_CANDIDATES`] that exists (`fonts-dejavu-core` on Debian provides the
//! first one). Without one the plot is still drawn, only without any text
//! (no title, tick labels, axis descriptions or legends).
//!
//! Non-finite values (NaN, ±inf) and missing normal-flow values are skipped:
//! lines are broken at them rather than drawn through them. Series whose
//! vectors have different lengths are cut to the shortest.

use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

use thiserror::Error;

/// A figure that could not be drawn or written.
#[derive(Debug, Error)]
pub enum PlotError {
    /// Drawing or encoding the figure failed.
    #[error("{}: cannot draw the plot: {detail}", path.display())]
    Draw {
        /// The figure's path.
        path: std::path::PathBuf,
        /// What failed.
        detail: String,
    },
    /// Writing the file failed.
    #[error(transparent)]
    Write(#[from] amc_video::VideoError),
}

/// Width of the figure in pixels.
pub const WIDTH: u32 = 1600;
/// Height of the figure in pixels.
pub const HEIGHT: u32 = 1000;

/// Font files tried, in order, for the figure's text (common Debian, Ubuntu,
/// Fedora and Arch locations).
pub const FONT_CANDIDATES: &[&str] = &[
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/TTF/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu-sans-fonts/DejaVuSans.ttf",
    "/usr/share/fonts/truetype/liberation/LiberationSans-Regular.ttf",
    "/usr/share/fonts/truetype/liberation2/LiberationSans-Regular.ttf",
    "/usr/share/fonts/truetype/freefont/FreeSans.ttf",
    "/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf",
];

/// The font family name the font is registered under with `plotters`.
const FONT_FAMILY: &str = "sans-serif";

/// One stabilization mode's per-frame data.
#[derive(Debug, Clone, Default)]
pub struct ModeSeries {
    /// Mode name: `"none"`, `"stabilize"` or `"saccade"`.
    pub mode: String,
    /// Frame times, seconds.
    pub t: Vec<f64>,
    /// Angular speed of the estimated camera orientation, deg/s.
    pub est_speed_dps: Vec<f64>,
    /// Angular speed of the stabilized view, deg/s.
    pub view_speed_dps: Vec<f64>,
    /// RMS normal flow of the output, px/frame (`None` on the first frame).
    pub normal_flow: Vec<Option<f64>>,
    /// A saccade happened at this frame.
    pub saccade: Vec<bool>,
}

/// Draws the figure for `series` and writes it to `path` as a 1600x1000 PNG.
///
/// The camera-estimate curve comes from the first series. An empty `series`
/// slice is not an error: it gives a PNG with the title and empty, labelled
/// axes. If no font from [`FONT_CANDIDATES`] is available, the figure is drawn
/// without any text rather than failing.
///
/// Errors: drawing or encoding failures are [`PlotError::Draw`], failures to
/// write the file [`PlotError::Write`]. The file is written atomically: on
/// error `path` is left as it was.
pub fn write_plot(path: &Path, title: &str, series: &[ModeSeries]) -> Result<(), PlotError> {
    let image_err = |detail: String| PlotError::Draw {
        path: path.to_path_buf(),
        detail,
    };
    let rgb = render(title, series, font_available()).map_err(image_err)?;
    let img = image::RgbImage::from_raw(WIDTH, HEIGHT, rgb)
        .ok_or_else(|| image_err("plot buffer has the wrong size".to_string()))?;
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| image_err(e.to_string()))?;
    amc_video::write_atomic(path, png.get_ref())?;
    Ok(())
}

/// Loads and registers the figure font once per process; `true` when text can
/// be drawn. Later calls return the first call's answer without touching the
/// file system or `plotters`' font table again.
fn font_available() -> bool {
    static FONT_OK: OnceLock<bool> = OnceLock::new();
    *FONT_OK.get_or_init(|| {
        for candidate in FONT_CANDIDATES {
            let Ok(bytes) = std::fs::read(candidate) else {
                continue;
            };
            // `register_font` wants `'static` bytes; this runs at most once per
            // successfully parsed font, so leaking is bounded.
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            if register_font(FONT_FAMILY, FontStyle::Normal, bytes).is_ok() {
                return true;
            }
        }
        false
    })
}

/// Line colour of a mode (matplotlib's default palette for the usual modes).
fn mode_color(mode: &str, index: usize) -> RGBColor {
    match mode {
        "none" => RGBColor(127, 127, 127),
        "stabilize" => RGBColor(31, 119, 180),
        "saccade" => RGBColor(214, 39, 40),
        _ => {
            let c = Palette99::pick(index + 3).to_rgba();
            RGBColor(c.0, c.1, c.2)
        }
    }
}

/// A drawing area on the in-memory bitmap.
type Area<'b> = DrawingArea<BitMapBackend<'b>, Shift>;
/// A chart with `f64` time and value axes on the in-memory bitmap.
type Chart<'a, 'b> =
    ChartContext<'a, BitMapBackend<'b>, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// Colour of the camera-estimate curve.
const CAMERA_COLOR: RGBColor = RGBColor(0, 0, 0);

/// Splits `(x, y)` samples into runs of consecutive finite points, so lines
/// are broken at missing or non-finite values instead of bridging them.
fn finite_runs(points: impl IntoIterator<Item = (f64, Option<f64>)>) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut run = Vec::new();
    for (x, y) in points {
        match y {
            Some(y) if x.is_finite() && y.is_finite() => run.push((x, y)),
            _ => {
                if !run.is_empty() {
                    runs.push(std::mem::take(&mut run));
                }
            }
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// A plotting range covering the finite values of `values`, always including
/// `floor` (0 for speeds and flows), with a little headroom; never empty.
fn value_range(values: impl IntoIterator<Item = f64>, floor: f64) -> std::ops::Range<f64> {
    let (mut lo, mut hi) = (floor, floor);
    for v in values.into_iter().filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let span = hi - lo;
    if span <= 0.0 || !span.is_finite() {
        return lo..lo + 1.0;
    }
    let pad = 0.05 * span;
    let lo = if lo < floor { lo - pad } else { lo };
    lo..hi + pad
}

/// The time range covered by all series (finite times only); `0..1` when
/// there is none, padded when all times are equal.
fn time_range(series: &[ModeSeries]) -> std::ops::Range<f64> {
    let mut it = series
        .iter()
        .flat_map(|s| s.t.iter().copied())
        .filter(|t| t.is_finite());
    let Some(first) = it.next() else {
        return 0.0..1.0;
    };
    let (lo, hi) = it.fold((first, first), |(lo, hi), t| (lo.min(t), hi.max(t)));
    if hi > lo {
        lo..hi
    } else {
        lo - 0.5..hi + 0.5
    }
}

/// Draws one line (possibly broken into runs) with a legend entry, if `text`.
fn draw_line<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    runs: Vec<Vec<(f64, f64)>>,
    style: ShapeStyle,
    label: &str,
    text: bool,
) -> Result<(), String> {
    for run in runs {
        chart
            .draw_series(LineSeries::new(run, style))
            .map_err(|e| e.to_string())?;
    }
    if text {
        // An empty series carries the legend entry, so a line with no finite
        // points still shows up in the legend.
        chart
            .draw_series(std::iter::empty::<PathElement<(f64, f64)>>())
            .map_err(|e| e.to_string())?
            .label(label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
    }
    Ok(())
}

/// Renders the figure into a `WIDTH`x`HEIGHT` RGB8 buffer. With `text` false
/// nothing that needs a font is drawn (no title, labels or legends).
fn render(title: &str, series: &[ModeSeries], text: bool) -> Result<Vec<u8>, String> {
    let mut buf = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let framed = root.margin(12, 8, 8, 8);
        let body = if text {
            framed
                .titled(title, (FONT_FAMILY, 34).into_font())
                .map_err(|e| e.to_string())?
        } else {
            framed
        };
        let panels = body.split_evenly((2, 1));
        let x_range = time_range(series);
        draw_speed_panel(&panels[0], series, x_range.clone(), text)?;
        draw_flow_panel(&panels[1], series, x_range, text)?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(buf)
}

/// Builds a chart on `area` with the shared look (margins, mesh, axis
/// descriptions when `text`).
fn make_chart<'a, 'b>(
    area: &'a Area<'b>,
    caption: &str,
    x_range: std::ops::Range<f64>,
    y_range: std::ops::Range<f64>,
    y_desc: &str,
    text: bool,
) -> Result<Chart<'a, 'b>, String> {
    let mut builder = ChartBuilder::on(area);
    builder.margin(16);
    if text {
        builder
            .caption(caption, (FONT_FAMILY, 24).into_font())
            .x_label_area_size(56)
            .y_label_area_size(90);
    }
    let mut chart = builder
        .build_cartesian_2d(x_range.clone(), y_range.clone())
        .map_err(|e| e.to_string())?;
    if text {
        chart
            .configure_mesh()
            .light_line_style(RGBColor(235, 235, 235))
            .bold_line_style(RGBColor(200, 200, 200))
            .x_desc("time (s)")
            .y_desc(y_desc)
            .label_style((FONT_FAMILY, 18).into_font())
            .axis_desc_style((FONT_FAMILY, 20).into_font())
            .draw()
            .map_err(|e| e.to_string())?;
    } else {
        // plotters' mesh always draws tick labels, which need a font: draw a
        // plain 10x10 grid and a frame instead.
        let (x0, x1) = (x_range.start, x_range.end);
        let (y0, y1) = (y_range.start, y_range.end);
        let grid = RGBColor(210, 210, 210);
        let lines = (1..10).flat_map(|k| {
            let f = k as f64 / 10.0;
            let x = x0 + f * (x1 - x0);
            let y = y0 + f * (y1 - y0);
            [
                PathElement::new(vec![(x, y0), (x, y1)], grid),
                PathElement::new(vec![(x0, y), (x1, y)], grid),
            ]
        });
        chart.draw_series(lines).map_err(|e| e.to_string())?;
        chart
            .draw_series(std::iter::once(Rectangle::new([(x0, y0), (x1, y1)], BLACK)))
            .map_err(|e| e.to_string())?;
    }
    Ok(chart)
}

/// Draws the legend box of `chart` (only with text, and only when there is
/// at least one entry, `any_entry`, so no empty box is drawn).
fn draw_legend<'a, 'b: 'a>(
    chart: &mut Chart<'a, 'b>,
    any_entry: bool,
    text: bool,
) -> Result<(), String> {
    if !text || !any_entry {
        return Ok(());
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(160, 160, 160))
        .label_font((FONT_FAMILY, 18).into_font())
        .draw()
        .map_err(|e| e.to_string())
}

/// Top panel: camera-estimate speed, each mode's view speed, saccade ticks.
fn draw_speed_panel(
    area: &Area<'_>,
    series: &[ModeSeries],
    x_range: std::ops::Range<f64>,
    text: bool,
) -> Result<(), String> {
    let shown: Vec<(usize, &ModeSeries)> = series
        .iter()
        .enumerate()
        .filter(|(_, s)| s.mode != "none")
        .collect();
    let est_values = series
        .first()
        .into_iter()
        .flat_map(|s| s.est_speed_dps.iter().copied());
    // A saccade turns the view by the whole accumulated deviation in one
    // frame (hundreds of deg/s): scaling the axis to those spikes would
    // flatten every other curve. The range leaves saccade frames out, the
    // curves are clipped at its top, and the ticks above mark the saccades.
    let view_values = shown.iter().flat_map(|(_, s)| {
        s.view_speed_dps
            .iter()
            .zip(s.saccade.iter().chain(std::iter::repeat(&false)))
            .filter(|(_, &sacc)| !sacc)
            .map(|(&v, _)| v)
    });
    let y = value_range(est_values.chain(view_values), 0.0);
    // Room above the curves for one row of saccade ticks per mode with any.
    let tick_modes: Vec<(usize, &ModeSeries)> = series
        .iter()
        .enumerate()
        .filter(|(_, s)| s.saccade.iter().any(|&b| b))
        .collect();
    let span = y.end - y.start;
    let row = 0.05 * span;
    let y_range = y.start..y.end + row * tick_modes.len() as f64;

    let mut chart = make_chart(
        area,
        "Angular speed",
        x_range,
        y_range.clone(),
        "angular speed (deg/s)",
        text,
    )?;

    if let Some(first) = series.first() {
        let runs = finite_runs(
            first
                .t
                .iter()
                .zip(&first.est_speed_dps)
                .map(|(&t, &v)| (t, Some(v))),
        );
        draw_line(
            &mut chart,
            runs,
            CAMERA_COLOR.stroke_width(2),
            "camera (estimate)",
            text,
        )?;
    }
    for &(i, s) in &shown {
        let runs = finite_runs(
            s.t.iter()
                .zip(&s.view_speed_dps)
                .map(|(&t, &v)| (t, Some(v.min(y.end)))),
        );
        let style = mode_color(&s.mode, i).stroke_width(2);
        draw_line(&mut chart, runs, style, &format!("view: {}", s.mode), text)?;
    }
    for (k, &(i, s)) in tick_modes.iter().enumerate() {
        let color = mode_color(&s.mode, i);
        let top = y_range.end - row * k as f64 - 0.15 * row;
        let bottom = top - 0.7 * row;
        let ticks =
            s.t.iter()
                .zip(&s.saccade)
                .filter(|&(t, &sacc)| sacc && t.is_finite())
                .map(move |(&t, _)| {
                    PathElement::new(vec![(t, bottom), (t, top)], color.stroke_width(2))
                });
        let anno = chart.draw_series(ticks).map_err(|e| e.to_string())?;
        if text {
            anno.label(format!("saccades ({})", s.mode))
                .legend(move |(x, y)| {
                    PathElement::new(
                        vec![(x + 12, y - 7), (x + 12, y + 7)],
                        color.stroke_width(2),
                    )
                });
        }
    }
    draw_legend(&mut chart, !series.is_empty(), text)
}

/// Bottom panel: RMS normal flow of each mode's output.
fn draw_flow_panel(
    area: &Area<'_>,
    series: &[ModeSeries],
    x_range: std::ops::Range<f64>,
    text: bool,
) -> Result<(), String> {
    let values = series
        .iter()
        .flat_map(|s| s.normal_flow.iter().filter_map(|v| *v));
    let y_range = value_range(values, 0.0);
    let mut chart = make_chart(
        area,
        "Normal flow of the output",
        x_range,
        y_range,
        "RMS normal flow (px/frame)",
        text,
    )?;
    for (i, s) in series.iter().enumerate() {
        let runs = finite_runs(s.t.iter().zip(&s.normal_flow).map(|(&t, &v)| (t, v)));
        let style = mode_color(&s.mode, i).stroke_width(2);
        draw_line(&mut chart, runs, style, &s.mode, text)?;
    }
    draw_legend(&mut chart, !series.is_empty(), text)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Synthetic data: a shaking camera, a smooth and a saccadic view.
    fn synthetic() -> Vec<ModeSeries> {
        let n = 300;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 30.0).collect();
        let est: Vec<f64> = t
            .iter()
            .map(|&t| 20.0 + 15.0 * (7.0 * t).sin().abs())
            .collect();
        let flow = |scale: f64| -> Vec<Option<f64>> {
            (0..n)
                .map(|i| (i > 0).then(|| scale * (1.0 + (i as f64 * 0.3).sin().abs())))
                .collect()
        };
        let mut saccade = vec![false; n];
        for i in (15..n).step_by(40) {
            saccade[i] = true;
        }
        let mut view_saccade: Vec<f64> = t.iter().map(|_| 1.0).collect();
        view_saccade[100] = f64::NAN; // a gap
        view_saccade[101] = f64::INFINITY;
        vec![
            ModeSeries {
                mode: "none".into(),
                t: t.clone(),
                est_speed_dps: est.clone(),
                view_speed_dps: est.clone(),
                normal_flow: flow(3.0),
                saccade: vec![false; n],
            },
            ModeSeries {
                mode: "stabilize".into(),
                t: t.clone(),
                est_speed_dps: est.clone(),
                view_speed_dps: t.iter().map(|&t| 2.0 + (t).sin()).collect(),
                normal_flow: flow(1.0),
                saccade: vec![false; n],
            },
            ModeSeries {
                mode: "saccade".into(),
                t,
                est_speed_dps: est,
                view_speed_dps: view_saccade,
                normal_flow: flow(0.5),
                saccade,
            },
        ]
    }

    fn check_png(path: &Path) -> image::RgbImage {
        let bytes = std::fs::read(path).unwrap();
        assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
        let img = image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
            .unwrap()
            .to_rgb8();
        assert_eq!(img.dimensions(), (WIDTH, HEIGHT));
        img
    }

    /// Number of pixels that are neither white nor a light grey (grid).
    fn dark_pixels(img: &image::RgbImage) -> usize {
        img.pixels()
            .filter(|p| p.0.iter().any(|&c| c < 150))
            .count()
    }

    #[test]
    fn plot_synthetic_series_is_png_of_right_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.png");
        write_plot(&path, "AMC: synthetic", &synthetic()).unwrap();
        let img = check_png(&path);
        assert!(dark_pixels(&img) > 1000, "plot looks empty");
        // Nothing but the plot is left in the directory.
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert_eq!(names.len(), 1);
        // Writing again over an existing file works (font registered once).
        write_plot(&path, "again", &synthetic()).unwrap();
        check_png(&path);
    }

    #[test]
    fn plot_empty_series_list_still_gives_png() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("empty.png");
        write_plot(&path, "nothing", &[]).unwrap();
        check_png(&path);
    }

    #[test]
    fn plot_degenerate_values() {
        // All zeros, single frame, all-NaN, empty vectors: no panic, a PNG.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("degenerate.png");
        let series = vec![
            ModeSeries {
                mode: "stabilize".into(),
                t: vec![0.0, 0.1, 0.2],
                est_speed_dps: vec![0.0; 3],
                view_speed_dps: vec![0.0; 3],
                normal_flow: vec![None, Some(0.0), Some(0.0)],
                saccade: vec![false, true, false],
            },
            ModeSeries {
                mode: "saccade".into(),
                t: vec![1.0],
                est_speed_dps: vec![f64::NAN],
                view_speed_dps: vec![f64::NEG_INFINITY],
                normal_flow: vec![None],
                saccade: vec![true],
            },
            ModeSeries {
                mode: "other".into(),
                ..Default::default()
            },
        ];
        write_plot(&path, "degenerate", &series).unwrap();
        check_png(&path);
    }

    #[test]
    fn plot_without_font_draws_no_text_but_succeeds() {
        let rgb = render("ignored", &synthetic(), false).unwrap();
        assert_eq!(rgb.len(), (WIDTH * HEIGHT * 3) as usize);
        let img = image::RgbImage::from_raw(WIDTH, HEIGHT, rgb).unwrap();
        assert!(dark_pixels(&img) > 1000);
    }

    #[test]
    fn plot_into_missing_directory_is_io_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("no/such/dir/fig.png");
        let err = write_plot(&path, "x", &synthetic()).unwrap_err();
        assert!(matches!(err, PlotError::Write(_)), "{err}");
        assert!(!path.exists());
    }

    #[test]
    fn helpers_handle_gaps_and_flat_ranges() {
        let runs = finite_runs(vec![
            (0.0, Some(1.0)),
            (1.0, None),
            (2.0, Some(f64::NAN)),
            (3.0, Some(2.0)),
            (4.0, Some(3.0)),
        ]);
        assert_eq!(runs, vec![vec![(0.0, 1.0)], vec![(3.0, 2.0), (4.0, 3.0)]]);
        assert_eq!(value_range([0.0, 0.0], 0.0), 0.0..1.0);
        assert_eq!(value_range([f64::NAN], 0.0), 0.0..1.0);
        let r = value_range([1.0, 10.0], 0.0);
        assert!(r.start == 0.0 && r.end > 10.0);
        assert_eq!(time_range(&[]), 0.0..1.0);
    }
}
