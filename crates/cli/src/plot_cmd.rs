//! `fairgrasp plot`: learning curves of one or more runs, read from each run directory's
//! `progress.csv`, overlaid in one figure (PNG or SVG): success rate and return against
//! environment steps and against wall time.

mod draw;
mod series;

pub use draw::register_fonts;

use anyhow::{Context, Result, bail};
use draw::{Figure, Format, RunCurves, XAxis};
use fairgrasp_rl::logger::{ProgressError, ProgressLog};
use series::Metric;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct PlotArgs {
    /// Run directories (each with a progress.csv), overlaid in this order.
    #[arg(required = true, value_name = "RUN_DIR")]
    pub runs: Vec<PathBuf>,
    /// The figure to write: a .png or .svg file.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Panels against environment steps, wall time or both.
    #[arg(long, value_enum, default_value_t = XAxis::Both)]
    pub x: XAxis,
    /// Moving average over this many logged points (1: none).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub smooth: u32,
    /// A title above the figure.
    #[arg(long)]
    pub title: Option<String>,
}

pub fn run(args: &PlotArgs) -> Result<()> {
    // Before reading anything: a wrong extension should not wait for the runs.
    let format = Format::from_path(&args.out)?;
    let mut runs = Vec::new();
    for (dir, label) in args.runs.iter().zip(labels(&args.runs)) {
        if let Some(run) = load_run(dir, label, args.smooth as usize)? {
            runs.push(run);
        }
    }
    if runs.is_empty() {
        bail!("nothing to plot: no run has a logged success rate or return yet");
    }
    let figure = Figure {
        runs: &runs,
        x: args.x,
        title: args.title.as_deref(),
        smooth: args.smooth as usize,
    };
    let bytes = figure.render(format)?;
    fairgrasp_env::atomic::write(&args.out, &bytes)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    let (w, h) = figure.size();
    println!(
        "wrote {} ({w}x{h}, {} run{})",
        args.out.display(),
        runs.len(),
        if runs.len() == 1 { "" } else { "s" }
    );
    Ok(())
}

/// A run's curves, or `None` (with a warning) when it has nothing to plot yet. A missing
/// directory or a missing or garbled `progress.csv` is an error: the figure would silently lack
/// a run the user asked for.
fn load_run(dir: &Path, label: String, smooth: usize) -> Result<Option<RunCurves>> {
    if !dir.is_dir() {
        bail!("{}: no such run directory", dir.display());
    }
    let path = dir.join("progress.csv");
    let log = match ProgressLog::read(&path) {
        Ok(log) => log,
        // A run that has just started has logged nothing yet.
        Err(ProgressError::Empty { .. }) => {
            eprintln!("warning: {}: empty, run skipped", path.display());
            return Ok(None);
        }
        Err(e) => return Err(e.into()),
    };
    let curve = |metric| {
        series::curve(&log, metric).map(|mut c| {
            c.points = series::smooth(&c.points, smooth);
            c
        })
    };
    let (success, ret) = (curve(Metric::Success), curve(Metric::Return));
    let Some(first) = success.as_ref().or(ret.as_ref()) else {
        eprintln!(
            "warning: {}: no row with {}, {} and a success rate or return; run skipped",
            path.display(),
            series::STEPS,
            series::SECONDS
        );
        return Ok(None);
    };
    if !first.column.starts_with("eval/") {
        eprintln!(
            "warning: {}: no evaluation rows; plotting the training episodes' statistics",
            path.display()
        );
    }
    Ok(Some(RunCurves {
        label,
        success,
        ret,
    }))
}

/// "name (algo)" for each run: the directory's name and the algorithm from `summary.json` (a
/// finished run) or `config.toml` (written when training starts). Runs with the same name
/// (`a/best`, `b/best`) are told apart by their path as given.
fn labels(dirs: &[PathBuf]) -> Vec<String> {
    let names: Vec<String> = dirs
        .iter()
        .map(|dir| {
            dir.canonicalize()
                .unwrap_or_else(|_| dir.clone())
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| dir.display().to_string())
        })
        .collect();
    dirs.iter()
        .zip(&names)
        .map(|(dir, name)| {
            let name = if names.iter().filter(|n| *n == name).count() > 1 {
                dir.display().to_string()
            } else {
                name.clone()
            };
            match algo(dir) {
                Some(algo) => format!("{name} ({algo})"),
                None => name,
            }
        })
        .collect()
}

fn algo(dir: &Path) -> Option<String> {
    let from_summary = || {
        let text = std::fs::read_to_string(dir.join("summary.json")).ok()?;
        let value: serde_json::Value = serde_json::from_str(&text).ok()?;
        Some(value.get("algo")?.as_str()?.to_string())
    };
    let from_config = || {
        let text = std::fs::read_to_string(dir.join("config.toml")).ok()?;
        let value: toml::Table = toml::from_str(&text).ok()?;
        Some(value.get("algo")?.as_str()?.to_string())
    };
    from_summary().or_else(from_config)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small run: rollout rows, evaluation rows with empty rollout cells, as the logger writes.
    fn write_run(root: &Path, name: &str, algo: &str, scale: f64) -> PathBuf {
        let dir = root.join(name);
        std::fs::create_dir_all(&dir).unwrap();
        let mut csv = String::from(
            "time/time_elapsed,rollout/ep_rew_mean,rollout/success_rate,time/total_timesteps,eval/success_rate,eval/mean_reward\n",
        );
        for k in 1..=20 {
            let t = k as f64;
            let s = (t / 20.0 * scale).min(1.0);
            csv += &format!("{},{},{s},{},,\n", t * 3.0, -100.0 + 80.0 * s, k * 5000);
            if k % 4 == 0 {
                csv += &format!(
                    "{},,,{},{s},{}\n",
                    t * 3.0 + 1.0,
                    k * 5000,
                    -90.0 + 85.0 * s
                );
            }
        }
        std::fs::write(dir.join("progress.csv"), csv).unwrap();
        std::fs::write(dir.join("config.toml"), format!("algo = \"{algo}\"\n")).unwrap();
        dir
    }

    fn args(runs: Vec<PathBuf>, out: PathBuf) -> PlotArgs {
        PlotArgs {
            runs,
            out,
            x: XAxis::Both,
            smooth: 1,
            title: Some("PPO against SAC".into()),
        }
    }

    #[test]
    fn two_runs_make_a_png_with_their_lines_and_text() {
        let tmp = tempfile::tempdir().unwrap();
        let a = write_run(tmp.path(), "a", "ppo", 1.0);
        let b = write_run(tmp.path(), "b", "sac", 2.0);
        let out = tmp.path().join("figs/curves.png");
        run(&args(vec![a, b], out.clone())).unwrap();

        let decoder =
            png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&out).unwrap()));
        let mut reader = decoder.read_info().unwrap();
        let mut pixels = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut pixels).unwrap();
        assert_eq!((info.width, info.height), (1240, 980));
        assert_eq!(info.color_type, png::ColorType::Rgb);
        let rgb: Vec<[u8; 3]> = pixels[..info.buffer_size()]
            .chunks(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        // Both runs' colours are drawn.
        for colour in [draw_palette(0), draw_palette(1)] {
            let n = rgb.iter().filter(|p| **p == colour).count();
            assert!(n > 500, "{n} pixels of {colour:?}");
        }
        // Text renders (the title and legend rows are near-black glyphs on white).
        let top = &rgb[..info.width as usize * 80];
        let dark = top.iter().filter(|p| p.iter().all(|c| *c < 80)).count();
        assert!(dark > 300, "{dark} dark pixels in the title and legend");
        // No stray temporary file is left beside the figure.
        let names: Vec<_> = std::fs::read_dir(out.parent().unwrap())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["curves.png"]);
    }

    fn draw_palette(i: usize) -> [u8; 3] {
        let plotters::style::RGBColor(r, g, b) = draw::PALETTE[i];
        [r, g, b]
    }

    #[test]
    fn an_svg_names_each_run_and_its_algorithm() {
        let tmp = tempfile::tempdir().unwrap();
        let a = write_run(tmp.path(), "deploy", "ppo", 1.0);
        let b = write_run(tmp.path(), "sac_plot", "sac", 2.0);
        let out = tmp.path().join("curves.svg");
        let mut args = args(vec![a, b], out.clone());
        args.x = XAxis::Time;
        args.smooth = 3;
        run(&args).unwrap();
        let svg = std::fs::read_to_string(&out).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..100]);
        for text in [
            "deploy (ppo)",
            "sac_plot (sac)",
            "success rate (%)",
            "wall time (s)",
            "mean episode return",
            "PPO against SAC",
            "Success rate (evaluation, mean of 3) against wall time",
        ] {
            assert!(svg.contains(text), "missing {text:?}");
        }
        assert!(
            !svg.contains("environment steps"),
            "--x time has no step panels"
        );
    }

    #[test]
    fn bad_input_is_an_error_naming_the_file_or_a_skipped_run() {
        let tmp = tempfile::tempdir().unwrap();
        let good = write_run(tmp.path(), "good", "ppo", 1.0);
        let out = tmp.path().join("c.png");

        let garbled = write_run(tmp.path(), "garbled", "ppo", 1.0);
        let path = garbled.join("progress.csv");
        let mut text = std::fs::read_to_string(&path).unwrap();
        text.insert_str(text.find('\n').unwrap() + 1, "1,2,x,4,,\n");
        std::fs::write(&path, text).unwrap();
        let err = run(&args(vec![good.clone(), garbled], out.clone())).unwrap_err();
        assert_eq!(
            format!("{err:#}"),
            format!(
                "{}:2: `x` in column `rollout/success_rate` is not a number",
                path.display()
            )
        );

        let missing = tmp.path().join("nope");
        let err = run(&args(vec![missing.clone()], out.clone())).unwrap_err();
        assert!(err.to_string().contains(&missing.display().to_string()));

        let no_csv = tmp.path().join("no_csv");
        std::fs::create_dir_all(&no_csv).unwrap();
        let err = run(&args(vec![no_csv.clone()], out.clone())).unwrap_err();
        assert!(err.to_string().contains("no_csv/progress.csv"), "{err}");

        let err = run(&args(vec![good.clone()], tmp.path().join("c.jpg"))).unwrap_err();
        assert!(
            err.to_string().contains("c.jpg: unknown figure format"),
            "{err}"
        );

        // Runs that have logged nothing yet are skipped; with nothing left it is an error.
        let empty = tmp.path().join("empty");
        std::fs::create_dir_all(&empty).unwrap();
        std::fs::write(empty.join("progress.csv"), "").unwrap();
        let header_only = tmp.path().join("header_only");
        std::fs::create_dir_all(&header_only).unwrap();
        std::fs::write(header_only.join("progress.csv"), "time/total_timesteps\n").unwrap();
        let err = run(&args(vec![empty.clone(), header_only.clone()], out.clone())).unwrap_err();
        assert!(err.to_string().starts_with("nothing to plot"), "{err}");
        run(&args(vec![empty, good, header_only], out.clone())).unwrap();
        assert!(out.exists());
    }

    #[test]
    fn runs_with_the_same_name_are_labelled_by_path() {
        let tmp = tempfile::tempdir().unwrap();
        let a = write_run(&tmp.path().join("x"), "best", "ppo", 1.0);
        let b = write_run(&tmp.path().join("y"), "best", "ppo", 1.0);
        let c = write_run(tmp.path(), "c", "sac", 1.0);
        assert_eq!(
            labels(&[a.clone(), b.clone(), c]),
            [
                format!("{} (ppo)", a.display()),
                format!("{} (ppo)", b.display()),
                "c (sac)".to_string()
            ]
        );
    }
}
