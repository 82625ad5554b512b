//! `vkdiff bench compare`: reports of one suite side by side (compare-llama-bench's way): a
//! column per report (device · driver · build), a row per figure, each value beside its speed
//! relative to the first report; as text, Markdown, or an HTML page with an SVG chart per group.

mod chart;

use crate::report::{show, Figure, Report};
use anyhow::{Context as _, Result};
use chart::{Bar, FigureBars};
use std::path::PathBuf;
use vkdiff_dataset::html_escape as escape;

#[derive(clap::Args)]
pub struct CompareArgs {
    /// Reports written by `vkdiff bench report --out`; the first is the baseline.
    #[arg(required = true, num_args = 2.., value_name = "REPORT.json")]
    reports: Vec<PathBuf>,
    /// Print Markdown instead of aligned text.
    #[arg(long)]
    markdown: bool,
    /// Also write a self-contained HTML page with a chart per group (SVG: speeds relative to the
    /// first report on a log scale).
    #[arg(long, value_name = "OUT.html")]
    html: Option<PathBuf>,
}

/// The reports read, each with its letter (A, B, …) and file.
struct Named {
    letter: char,
    file: PathBuf,
    report: Report,
}

fn read(args: &CompareArgs) -> Result<Vec<Named>> {
    let mut out: Vec<Named> = Vec::new();
    for (k, file) in args.reports.iter().enumerate() {
        let text = std::fs::read_to_string(file).with_context(|| format!("{}: cannot read it", file.display()))?;
        let report: Report = serde_json::from_str(&text)
            .map_err(|e| vkdiff_args::Usage(format!("{}: not a `vkdiff bench report` JSON ({e})", file.display())))?;
        if let Some(first) = out.first() {
            vkdiff_args::ensure_usage(first.report.suite == report.suite, || {
                format!(
                    "{} is `{}` and {} is `{}`: reports of different suites do not compare",
                    first.file.display(),
                    first.report.suite,
                    file.display(),
                    report.suite
                )
            })?;
        }
        out.push(Named { letter: (b'A' + (k as u8 % 26)) as char, file: file.clone(), report });
    }
    Ok(out)
}

/// Every figure id in the order the reports list them (the first's, then ones it lacks), but
/// for the rows that repeat a figure against the compiled reference.
fn figure_ids(reports: &[Named]) -> Vec<(String, String, String)> {
    let mut ids: Vec<(String, String, String)> = Vec::new();
    for f in reports.iter().flat_map(|r| &r.report.figures).filter(|f| !f.is_compiled_twin()) {
        if !ids.iter().any(|(id, ..)| *id == f.id) {
            ids.push((f.id.clone(), f.group.clone(), f.label.clone()));
        }
    }
    ids
}

fn figure<'a>(report: &'a Report, id: &str) -> Option<&'a Figure> {
    report.figures.iter().find(|f| f.id == id)
}

/// Speed relative to `base` (above 1: faster), for times and rates alike.
fn relative(f: &Figure, base: &Figure) -> f64 {
    if f.higher_is_better {
        f.runs.median / base.runs.median
    } else {
        base.runs.median / f.runs.median
    }
}

/// A row's cells: each report's median, and after the first its relative speed.
fn cells(reports: &[Named], id: &str) -> Vec<String> {
    let base = figure(&reports[0].report, id);
    reports
        .iter()
        .enumerate()
        .map(|(k, r)| match (figure(&r.report, id), base) {
            (Some(f), Some(b)) if k > 0 => format!("{} ({:.2}×)", show(f.runs.median, &f.unit), relative(f, b)),
            (Some(f), _) => show(f.runs.median, &f.unit),
            (None, _) => "—".into(),
        })
        .collect()
}

pub fn run(args: &CompareArgs) -> Result<()> {
    let reports = read(args)?;
    let ids = figure_ids(&reports);
    let header: Vec<String> = reports.iter().map(|r| format!("{}: {}", r.letter, r.report.system.column())).collect();
    if args.markdown {
        println!("{}\n", reports[0].report.suite);
        println!("| figure | {} |", reports.iter().map(|r| r.letter.to_string()).collect::<Vec<_>>().join(" | "));
        println!("|---|{}", "---|".repeat(reports.len()));
        for (id, _, label) in &ids {
            println!("| {label} | {} |", cells(&reports, id).join(" | "));
        }
        println!();
        for line in &header {
            println!("- {line}");
        }
    } else {
        println!("{}", reports[0].report.suite);
        for line in &header {
            println!("  {line}");
        }
        let width = ids.iter().map(|(_, _, l)| l.chars().count()).max().unwrap_or(0).min(60);
        for (id, _, label) in &ids {
            let short: String = label.chars().take(width).collect();
            println!("{short:<width$}  {}", cells(&reports, id).iter().map(|c| format!("{c:<22}")).collect::<String>());
        }
    }
    if let Some(html) = &args.html {
        vkdiff_formats::atomic::write_atomic(html, page(&reports, &ids).as_bytes())?;
        eprintln!("compare: written to {}", html.display());
    }
    Ok(())
}

/// A group's chart: for each figure a bar per report holding it, its speed relative to the
/// first report (a figure the first lacks has no bars).
fn chart(reports: &[Named], ids: &[(String, String, String)], group: &str) -> String {
    let figures: Vec<FigureBars> = (ids.iter().filter(|(_, g, _)| g == group).enumerate())
        .filter_map(|(n, (id, _, label))| {
            let base = figure(&reports[0].report, id)?;
            let bars = reports.iter().filter_map(|r| {
                let f = figure(&r.report, id)?;
                Some(Bar { letter: r.letter, ratio: relative(f, base), value: show(f.runs.median, &f.unit) })
            });
            Some(FigureBars { number: n + 1, label: label.clone(), bars: bars.collect() })
        })
        .collect();
    chart::svg(&format!("{group}: speed relative to A"), &figures)
}

fn page(reports: &[Named], ids: &[(String, String, String)]) -> String {
    let mut groups: Vec<&str> = Vec::new();
    for (_, g, _) in ids {
        if !groups.contains(&g.as_str()) {
            groups.push(g);
        }
    }
    let mut body = String::new();
    body += &format!("<h1>{}</h1>\n<ul>\n", escape(&reports[0].report.suite));
    for r in reports {
        let s = &r.report.system;
        body += &format!(
            "<li><b>{}</b>: {} · {} · Vulkan {} · {} · {} · vkdiff {} · {} <code>{}</code></li>\n",
            r.letter,
            escape(&s.device),
            escape(&s.driver),
            escape(&s.vulkan),
            escape(&s.cpu),
            escape(&s.os),
            escape(&s.vkdiff),
            escape(&s.date),
            escape(&r.file.display().to_string())
        );
    }
    body += "</ul>\n";
    for group in groups {
        body += &format!("<h2>{}</h2>\n<table>\n<tr><th>#</th><th>figure</th>", escape(group));
        for r in reports {
            body += &format!("<th>{}</th>", r.letter);
        }
        body += "</tr>\n";
        for (n, (id, _, label)) in ids.iter().filter(|(_, g, _)| g == group).enumerate() {
            body += &format!("<tr><td>{}</td><td>{}</td>", n + 1, escape(label));
            for cell in cells(reports, id) {
                body += &format!("<td>{}</td>", escape(&cell));
            }
            body += "</tr>\n";
        }
        body += &format!("</table>\n<figure>\n{}</figure>\n", chart(reports, ids, group));
    }
    format!(
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>vkdiff bench compare</title>\n<style>\nbody \
         {{ background: #ffffff; color: #1e1e1e; font-family: sans-serif; margin: 24px; }}\ntable {{ border-collapse: \
         collapse; margin: 8px 0; }}\ntd, th {{ border: 1px solid #bbb; padding: 3px 8px; text-align: left; }}\nfigure \
         {{ margin: 8px 0 24px; }}\n</style></head>\n<body>\n{body}</body></html>\n"
    )
}
