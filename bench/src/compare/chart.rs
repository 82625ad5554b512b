//! A group's chart as inline SVG with real text: for each figure a bar per report, its length
//! the speed relative to the first report on a log scale, so that reports 100× apart both show.
//! Every bar starts at the axis's left end, at least a decade below the slowest ratio, so no bar
//! (the first report's own 1× included) has zero length.

use vkdiff_dataset::html_escape as escape;

/// One report's bar: its letter, its speed relative to the first report, and its value as shown.
pub struct Bar {
    pub letter: char,
    pub ratio: f64,
    pub value: String,
}

/// One figure's bars, under its number and label.
pub struct FigureBars {
    pub number: usize,
    pub label: String,
    pub bars: Vec<Bar>,
}

const WIDTH: f64 = 960.0;
/// The plot's left edge (after the letters) and its width (the values' text goes right of it).
const PLOT_X: f64 = 40.0;
const PLOT_WIDTH: f64 = 680.0;
const HEADING: f64 = 20.0;
const ROW: f64 = 22.0;
const BAR: f64 = 16.0;
const GAP: f64 = 12.0;
const AXIS: f64 = 34.0;
/// A report's colour, by its place (A, B, …).
const COLOURS: [&str; 6] = ["#466eaa", "#d2691e", "#2e8b57", "#8b3a8b", "#b22222", "#5f6b73"];

/// The log scale's ends in decades: a decade below the slowest ratio's, and the fastest's ceiling.
pub fn decades(ratios: impl Iterator<Item = f64>) -> (i32, i32) {
    let (lo, hi) = ratios.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| (lo.min(r), hi.max(r)));
    if !lo.is_finite() {
        return (-1, 0);
    }
    let low = lo.log10().floor() as i32 - 1;
    (low, (hi.log10().ceil() as i32).max(low + 1))
}

/// "0.01×", "1×", "100×": a decade's tick label.
pub fn decade_text(decade: i32) -> String {
    if decade >= 0 {
        format!("1{}×", "0".repeat(decade as usize))
    } else {
        format!("0.{}1×", "0".repeat((-decade - 1) as usize))
    }
}

/// A ratio with three significant digits: 1.05×, 0.0123×, 153×.
pub fn ratio_text(ratio: f64) -> String {
    let digits = (2 - ratio.log10().floor() as i32).max(0) as usize;
    format!("{ratio:.digits$}×")
}

/// The chart of `figures`, titled `title`.
pub fn svg(title: &str, figures: &[FigureBars]) -> String {
    let drawn = |b: &&Bar| b.ratio.is_finite() && b.ratio > 0.0;
    let (low, high) = decades(figures.iter().flat_map(|f| f.bars.iter().filter(drawn).map(|b| b.ratio)));
    let x = |ratio: f64| PLOT_X + (ratio.log10() - low as f64) / (high - low) as f64 * PLOT_WIDTH;
    // The decades' lines, behind each figure's bars (not across its heading).
    let grid = |top: f64, bottom: f64| -> String {
        (low..=high)
            .map(|decade| {
                let (at, stroke) = (x(10f64.powi(decade)), if decade == 0 { "#1e1e1e" } else { "#c8c8c8" });
                format!("<line class=\"grid\" x1=\"{at:.1}\" y1=\"{top:.1}\" x2=\"{at:.1}\" y2=\"{bottom:.1}\" stroke=\"{stroke}\"/>\n")
            })
            .collect()
    };
    let mut body = format!("<text class=\"title\" x=\"0\" y=\"16\" font-weight=\"bold\">{}</text>\n", escape(title));
    let mut y = 28.0;
    for figure in figures {
        body += &format!(
            "<text class=\"figure\" x=\"0\" y=\"{:.1}\">{} · {}</text>\n",
            y + 14.0,
            figure.number,
            escape(&figure.label)
        );
        y += HEADING;
        body += &grid(y, y + figure.bars.len() as f64 * ROW - (ROW - BAR));
        for bar in &figure.bars {
            body += &bar_row(bar, y, drawn(&bar).then(|| x(bar.ratio)));
            y += ROW;
        }
        y += GAP;
    }
    for decade in low..=high {
        body += &format!(
            "<text class=\"tick\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{}</text>\n",
            x(10f64.powi(decade)),
            y + 2.0,
            decade_text(decade)
        );
    }
    body += &format!(
        "<text class=\"axis\" x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">speed relative to A (log scale; \
         right is faster)</text>\n",
        PLOT_X + PLOT_WIDTH / 2.0,
        y + 20.0
    );
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{WIDTH:.0}\" height=\"{:.0}\" font-family=\"sans-serif\" \
         font-size=\"13\" shape-rendering=\"crispEdges\">\n{body}</svg>\n",
        y + AXIS
    )
}

/// One report's row at `y`: its letter, its bar to `end` (none without a ratio) and its text.
fn bar_row(bar: &Bar, y: f64, end: Option<f64>) -> String {
    let middle = y + BAR / 2.0 + 4.0;
    let mut row =
        format!("<text class=\"letter\" x=\"{:.1}\" y=\"{middle:.1}\">{}</text>\n", PLOT_X - 24.0, bar.letter);
    let Some(end) = end else {
        let text = format!("no ratio · {}", escape(&bar.value));
        return row + &format!("<text class=\"value\" x=\"{:.1}\" y=\"{middle:.1}\">{text}</text>\n", PLOT_X + 6.0);
    };
    let colour = COLOURS[(bar.letter as usize - 'A' as usize) % COLOURS.len()];
    row += &format!(
        "<rect class=\"bar\" data-report=\"{}\" x=\"{PLOT_X:.1}\" y=\"{y:.1}\" width=\"{:.1}\" height=\"{BAR:.1}\" \
         fill=\"{colour}\"/>\n",
        bar.letter,
        end - PLOT_X
    );
    row + &format!(
        "<text class=\"value\" data-report=\"{}\" x=\"{:.1}\" y=\"{middle:.1}\">{} · {}</text>\n",
        bar.letter,
        end + 6.0,
        ratio_text(bar.ratio),
        escape(&bar.value)
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The number in `attribute="…"` of the first element in `svg` that holds `marker`.
    fn attribute(svg: &str, marker: &str, attribute: &str) -> f64 {
        let element = svg.lines().find(|l| l.contains(marker)).unwrap_or_else(|| panic!("no {marker} in {svg}"));
        let after = element.split(&format!(" {attribute}=\"")).nth(1).unwrap();
        after[..after.find('"').unwrap()].parse().unwrap()
    }

    fn bars(ratios: &[(char, f64)]) -> FigureBars {
        let bars = ratios.iter().map(|&(letter, ratio)| Bar { letter, ratio, value: format!("{letter} value") });
        FigureBars { number: 1, label: "the UNet <f16>".into(), bars: bars.collect() }
    }

    #[test]
    fn ratios_a_hundred_apart_both_show_on_a_log_scale() {
        let svg = svg("unet", &[bars(&[('A', 1.0), ('B', 0.01)])]);
        // The axis runs from 0.001× (a decade below B's) to 1×.
        assert_eq!(decades([1.0, 0.01].into_iter()), (-3, 0));
        let tick = |label: &str| attribute(&svg, &format!(">{label}</text>"), "x");
        let end = |letter: char| {
            let marker = format!("class=\"bar\" data-report=\"{letter}\"");
            attribute(&svg, &marker, "x") + attribute(&svg, &marker, "width")
        };
        assert_eq!((tick("0.001×"), tick("1×")), (PLOT_X, PLOT_X + PLOT_WIDTH));
        // Each bar ends at its ratio's tick: a decade is a third of the plot.
        assert!((end('A') - tick("1×")).abs() < 0.11 && (end('B') - tick("0.01×")).abs() < 0.11, "{svg}");
        assert!((tick("0.01×") - tick("0.001×") - PLOT_WIDTH / 3.0).abs() < 0.11);
        assert!(attribute(&svg, "data-report=\"B\"", "width") >= PLOT_WIDTH / 3.0 - 0.1, "B is a decade long");
        // Real text: the figure, the letters and each bar's ratio with its value, escaped.
        for text in [">1 · the UNet &lt;f16&gt;</text>", ">A</text>", ">B</text>", ">1.00× · A value</text>"] {
            assert!(svg.contains(text), "{text} in {svg}");
        }
        assert!(svg.contains(">0.0100× · B value</text>"), "{svg}");
    }

    #[test]
    fn ticks_and_ratios_read_as_people_write_them() {
        assert_eq!([-3, -1, 0, 2].map(decade_text), ["0.001×", "0.1×", "1×", "100×"]);
        assert_eq!([1.05, 0.0123, 153.4, 12.34].map(ratio_text), ["1.05×", "0.0123×", "153×", "12.3×"]);
        assert_eq!(decades([1.0, 1.05].into_iter()), (-1, 1));
        assert_eq!(decades([0.5, 20.0].into_iter()), (-2, 2));
        assert_eq!(decades(std::iter::empty()), (-1, 0));
    }

    #[test]
    fn a_bar_without_a_ratio_says_so_and_draws_nothing() {
        let svg = svg("image", &[bars(&[('A', 1.0), ('B', f64::INFINITY)])]);
        assert_eq!(svg.matches("class=\"bar\"").count(), 1, "{svg}");
        assert!(svg.contains(">no ratio · B value</text>"), "{svg}");
    }
}
