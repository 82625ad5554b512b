//! One colour per category, as a segmentation ControlNet expects it: a category named as an ADE20K
//! class takes that class's colour in the palette those ControlNets were trained on; any other takes
//! a colour of a fixed sequence; the background is black, which the ADE20K palette does not use.

use super::ade20k::ADE20K;
use crate::coco::Category;
use serde::Serialize;

/// The background's colour.
pub const BACKGROUND: [u8; 3] = [0, 0, 0];

/// The colour a category takes, and the ADE20K class it was matched to.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CategoryColour {
    pub id: u32,
    pub name: String,
    pub rgb: [u8; 3],
    /// The ADE20K class whose colour it took; None for a colour of the fixed sequence.
    pub ade20k: Option<&'static str>,
}

/// The ADE20K class a category's name names: compared without case, with `_` and `-` as spaces.
fn ade20k_class(name: &str) -> Option<(&'static str, [u8; 3])> {
    let wanted = name.trim().to_lowercase().replace(['_', '-'], " ");
    ADE20K.iter().find(|(class, _)| *class == wanted).copied()
}

/// The k-th colour of the fixed sequence: hues a golden-ratio turn apart, bright and saturated.
fn sequence_colour(k: usize) -> [u8; 3] {
    let hue = (k as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let (saturation, value) = (0.7, 0.95);
    let chroma = value * saturation;
    let x = chroma * (1.0 - (hue % 2.0 - 1.0).abs());
    let (r, g, b) = match hue as u32 {
        0 => (chroma, x, 0.0),
        1 => (x, chroma, 0.0),
        2 => (0.0, chroma, x),
        3 => (0.0, x, chroma),
        4 => (x, 0.0, chroma),
        _ => (chroma, 0.0, x),
    };
    let m = value - chroma;
    [r, g, b].map(|c| ((c + m) * 255.0).round() as u8)
}

/// Each category's colour, in `categories`' order; those that match no ADE20K class take the
/// sequence's colours in that order.
pub fn category_colours(categories: &[Category]) -> Vec<CategoryColour> {
    let mut unmatched = 0;
    categories
        .iter()
        .map(|c| {
            let (rgb, ade20k) = match ade20k_class(&c.name) {
                Some((class, rgb)) => (rgb, Some(class)),
                None => {
                    unmatched += 1;
                    (sequence_colour(unmatched - 1), None)
                }
            };
            CategoryColour { id: c.id, name: c.name.clone(), rgb, ade20k }
        })
        .collect()
}

/// RGB8 segmentation of a frame's `ids` (0 background), instance k being of category
/// `instance_categories[k - 1]`, coloured by `colours`.
pub fn segmentation_image(ids: &[u16], instance_categories: &[u32], colours: &[CategoryColour]) -> Vec<u8> {
    let colour_of_instance: Vec<[u8; 3]> = instance_categories
        .iter()
        .map(|id| colours.iter().find(|c| c.id == *id).map_or(BACKGROUND, |c| c.rgb))
        .collect();
    ids.iter().flat_map(|&id| if id == 0 { BACKGROUND } else { colour_of_instance[id as usize - 1] }).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn category(id: u32, name: &str) -> Category {
        Category::new(id, name, name)
    }

    #[test]
    fn ade20k_names_take_their_colours_and_others_the_sequence() {
        let colours = category_colours(&[category(1, "Tree"), category(2, "mushroom"), category(3, "traffic_light")]);
        assert_eq!((colours[0].rgb, colours[0].ade20k), ([4, 200, 3], Some("tree")));
        assert_eq!(colours[1].ade20k, None);
        assert_eq!(colours[1].rgb, sequence_colour(0));
        assert_eq!(colours[2].ade20k, Some("traffic light"));
        assert!(ADE20K.iter().all(|(_, rgb)| *rgb != BACKGROUND));
        let image = segmentation_image(&[0, 1, 2], &[2, 1], &colours);
        assert_eq!(image, [BACKGROUND, colours[1].rgb, colours[0].rgb].concat());
    }
}
