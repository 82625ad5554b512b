//! An RGB canvas with what the statistics' charts and the preview's contact sheet draw on it:
//! filled rectangles and text in a 3×5 pixel font (scaled), so that neither needs a font file.

use vkdiff_render::png_out::rgb8;

pub type Rgb = [u8; 3];

pub struct Canvas {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<u8>,
}

/// Each glyph's 5 rows of 3 bits, the high bit leftmost.
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [1, 2, 2, 2, 1],
        ')' => [4, 2, 2, 2, 4],
        '%' => [5, 1, 2, 4, 5],
        '=' => [0, 7, 0, 7, 0],
        '<' => [1, 2, 4, 2, 1],
        '>' => [4, 2, 1, 2, 4],
        '_' => [0, 0, 0, 0, 7],
        '#' => [5, 7, 5, 7, 5],
        ' ' => [0; 5],
        _ => [7, 7, 7, 7, 7],
    }
}

impl Canvas {
    pub fn new(width: usize, height: usize, fill: Rgb) -> Canvas {
        Canvas { width, height, pixels: fill.repeat(width * height) }
    }

    pub fn put(&mut self, x: i64, y: i64, color: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let at = 3 * (y as usize * self.width + x as usize);
            self.pixels[at..at + 3].copy_from_slice(&color);
        }
    }

    pub fn rect(&mut self, x: i64, y: i64, width: i64, height: i64, color: Rgb) {
        for yy in y..y + height {
            for xx in x..x + width {
                self.put(xx, yy, color);
            }
        }
    }

    /// `text` with its top-left at (x, y), each font pixel `scale` pixels wide.
    pub fn text(&mut self, x: i64, y: i64, text: &str, scale: i64, color: Rgb) {
        for (k, c) in text.chars().enumerate() {
            for (row, bits) in glyph(c).iter().enumerate() {
                for col in 0..3 {
                    if bits & (4 >> col) != 0 {
                        let (gx, gy) = (x + (k as i64 * 4 + col) * scale, y + row as i64 * scale);
                        self.rect(gx, gy, scale, scale, color);
                    }
                }
            }
        }
    }

    /// The width `text` takes at `scale`.
    pub fn text_width(text: &str, scale: i64) -> i64 {
        (text.chars().count() as i64 * 4 - 1).max(0) * scale
    }

    /// Copies an RGB image into the canvas at (x, y).
    pub fn blit(&mut self, x: i64, y: i64, width: usize, height: usize, rgb: &[u8]) {
        for yy in 0..height {
            for xx in 0..width {
                let at = 3 * (yy * width + xx);
                self.put(x + xx as i64, y + yy as i64, [rgb[at], rgb[at + 1], rgb[at + 2]]);
            }
        }
    }

    pub fn png(&self) -> Vec<u8> {
        rgb8(self.width as u32, self.height as u32, &self.pixels)
    }
}

/// A bar chart: `bars` as (label under the bar, value), a title and the axis's name.
pub fn bar_chart(title: &str, axis: &str, bars: &[(String, u64)]) -> Canvas {
    const S: i64 = 2;
    let (left, top, bottom, bar_width) = (70i64, 40i64, 60i64, 40i64.max(560 / bars.len().max(1) as i64).min(80));
    let plot_height = 300i64;
    let width = left + bar_width * bars.len() as i64 + 30;
    let height = top + plot_height + bottom;
    let mut canvas = Canvas::new(width.max(360) as usize, height as usize, [255, 255, 255]);
    let ink = [30, 30, 30];
    canvas.text(10, 10, title, S, ink);
    let max = bars.iter().map(|b| b.1).max().unwrap_or(0).max(1);
    // Axis and the top value.
    canvas.rect(left - 2, top, 2, plot_height + 2, ink);
    canvas.rect(left - 2, top + plot_height, bar_width * bars.len() as i64 + 4, 2, ink);
    let top_label = max.to_string();
    canvas.text(left - 8 - Canvas::text_width(&top_label, S), top, &top_label, S, ink);
    canvas.text(left - 8 - Canvas::text_width("0", S), top + plot_height - 10, "0", S, ink);
    for (k, (label, value)) in bars.iter().enumerate() {
        let h = (*value as f64 / max as f64 * plot_height as f64).round() as i64;
        let x = left + k as i64 * bar_width;
        canvas.rect(x + 3, top + plot_height - h, bar_width - 6, h, [70, 110, 170]);
        let scale = if Canvas::text_width(label, S) <= bar_width - 2 { S } else { 1 };
        let lx = x + (bar_width - Canvas::text_width(label, scale)) / 2;
        canvas.text(lx, top + plot_height + 8 + (k as i64 % 2) * 12 * (2 - scale), label, scale, ink);
    }
    canvas.text(left, height - 18, axis, S, ink);
    canvas
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_bars_land_where_they_are_drawn() {
        let mut c = Canvas::new(20, 10, [0, 0, 0]);
        c.text(1, 1, "1", 1, [255, 255, 255]);
        // "1" is 010 / 110 / 010 / 010 / 111.
        let lit = |c: &Canvas, x: usize, y: usize| c.pixels[3 * (y * c.width + x)] == 255;
        assert!(lit(&c, 2, 1) && !lit(&c, 1, 1) && lit(&c, 1, 2) && lit(&c, 3, 5) && !lit(&c, 3, 4));
        let chart = bar_chart("T", "X", &[("a".into(), 10), ("b".into(), 5)]);
        let blue = |x: i64, y: i64| chart.pixels[3 * (y as usize * chart.width + x as usize)..][..3] == [70, 110, 170];
        // The first bar is full height, the second half of it.
        assert!(blue(70 + 40, 40 + 10) && !blue(70 + 80 + 40, 40 + 100) && blue(70 + 80 + 40, 40 + 200));
    }
}
