//! A report as Markdown: the machine, then a row per figure (median, spread, first run, peak
//! memory, the reference and the speed-up), then how to make it again. Pasted as it is into an
//! issue or a discussion, as llama-bench's rows are.

use super::figure::{show, Reference};
use super::Report;

pub fn markdown(report: &Report) -> String {
    let s = &report.system;
    let mut out = format!(
        "## {} on {}\n\n{} · {} · Vulkan {} · products: f16 {}, f32 {} · subgroups of {}\n{} · {} · vkdiff {} · \
         {}\nmodels: {}\n\n",
        report.suite,
        s.device,
        s.vendor,
        s.driver,
        s.vulkan,
        s.kernels_f16,
        s.kernels_f32,
        s.subgroup_size,
        s.cpu,
        s.os,
        s.vkdiff,
        s.date,
        report.models
    );
    out += "| figure | vkdiff (median) | spread | first run | peak MiB | reference | speed-up |\n";
    out += "|---|---|---|---|---|---|---|\n";
    let mut notes = Vec::new();
    for f in &report.figures {
        let share = f.peak_share.map_or(String::new(), |p| format!(" ({:.1} % of the matrix peak)", 100.0 * p));
        let reference = match &f.reference {
            Reference::Measured { value, what } => format!("{} ({what})", show(*value, &f.unit)),
            Reference::Missing { why } => format!("— ({why})"),
        };
        out += &format!(
            "| {} | {}{share} | ±{:.1} % of {} | {} | {} | {} | {} |\n",
            f.label,
            show(f.runs.median, &f.unit),
            50.0 * f.runs.spread(),
            f.runs.count,
            f.first_run.map_or("—".into(), |v| show(v, if f.unit == "TFLOP/s" { "s" } else { &f.unit })),
            f.peak_mib.map_or("—".into(), |m| format!("{m:.0}")),
            reference,
            f.speedup().map_or("—".into(), |x| format!("{x:.2}×")),
        );
        if !f.parts.is_empty() {
            let parts: Vec<String> = f.parts.iter().map(|(name, v)| format!("{name} {}", show(*v, &f.unit))).collect();
            notes.push(format!("- {}: {}", f.label, parts.join(", ")));
        }
        if let Some(note) = &f.note {
            notes.push(format!("- {}: {note}", f.label));
        }
    }
    if !notes.is_empty() {
        out += "\n";
        out += &notes.join("\n");
        out += "\n";
    }
    out += &format!("\nReproduce by: `{}`\n", s.command);
    out
}
