//! The preview's HTML page: the figures in a grid, a sticky header with the layer switch and the
//! legend, and the script that switches layers (also from the page's #hash).

/// The page around `figures`, with a layer switch for the image, the depth, the depth control,
/// the init image and each of `controls` (the kinds of `--controls` the figures carry), and a
/// checkbox for the instance outlines and each of `overlays` (amodal outlines, keypoints).
pub fn page(title: &str, legend: &str, figures: &str, controls: &[String], overlays: &[&str]) -> String {
    let overlay_css: String = overlays
        .iter()
        .map(|o| format!("\n.stack img.{o} {{ position: absolute; top: 0; left: 0; }}\nbody.{o} .stack img.{o} {{ display: block; }}"))
        .collect();
    let overlay_boxes: String = overlays
        .iter()
        .map(|o| {
            format!(
                "\n<label><input type=\"checkbox\" class=\"overlay\" value=\"{o}\" checked> {}</label>",
                overlay_label(o)
            )
        })
        .collect();
    let body_classes: String = overlays.iter().map(|o| format!(" {o}")).collect();
    let layer_css: String =
        controls.iter().map(|k| format!(",\nbody[data-layer=\"control-{k}\"] img.control-{k}")).collect();
    let layer_radios: String = controls
        .iter()
        .map(|k| format!("\n<label><input type=\"radio\" name=\"layer\" value=\"control-{k}\"> {k}</label>"))
        .collect();
    let layer_names: String = controls.iter().map(|k| format!(", 'control-{k}'")).collect();
    format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body {{ background: #181a1b; color: #ddd; font: 14px system-ui, sans-serif; margin: 16px; }}
header {{ position: sticky; top: 0; background: #181a1b; padding: 8px 0; z-index: 2; }}
main {{ display: grid; grid-template-columns: repeat(auto-fill, minmax(320px, 1fr)); gap: 16px; }}
figure {{ margin: 0; }}
.stack {{ position: relative; }}
.stack img {{ display: none; width: 100%; image-rendering: pixelated; }}
.stack img.outline {{ position: absolute; top: 0; left: 0; }}
body.outlines .stack img.outline {{ display: block; }}{overlay_css}
body[data-layer="image"] img.image, body[data-layer="depth"] img.depth,
body[data-layer="control"] img.control, body[data-layer="init"] img.init{layer_css} {{ display: block; }}
figcaption {{ margin-top: 4px; }}
.prompt {{ color: #999; }}
label {{ margin-right: 12px; }}
.legend span {{ margin-right: 14px; }}
.legend i {{ display: inline-block; width: 12px; height: 12px; margin-right: 4px; vertical-align: -1px; }}
</style></head>
<body class="outlines{body_classes}" data-layer="image">
<header><strong>{title}</strong><br>
<label><input type="checkbox" id="outlines" checked> instance outlines</label>{overlay_boxes}
<label><input type="radio" name="layer" value="image" checked> image</label>
<label><input type="radio" name="layer" value="depth"> depth</label>
<label><input type="radio" name="layer" value="control"> control</label>
<label><input type="radio" name="layer" value="init"> init</label>{layer_radios}
{legend}
</header>
<main>
{figures}</main>
<script>
// The layer shown: the radio buttons, or the page's #hash (preview.html#depth).
function show(layer) {{
  document.body.dataset.layer = layer;
  for (const r of document.querySelectorAll('input[name=layer]')) r.checked = r.value === layer;
}}
for (const r of document.querySelectorAll('input[name=layer]')) r.onchange = () => show(r.value);
document.getElementById('outlines').onchange = e => document.body.classList.toggle('outlines', e.target.checked);
for (const c of document.querySelectorAll('input.overlay')) c.onchange = () => document.body.classList.toggle(c.value, c.checked);
const hash = location.hash.slice(1).split(',');
if (['image', 'depth', 'control', 'init'{layer_names}].includes(hash[0])) show(hash[0]);
if (hash.includes('nooutlines')) {{ document.body.classList.remove('outlines'); document.getElementById('outlines').checked = false; }}
</script>
</body></html>
"#
    )
}

/// What an overlay's checkbox says.
fn overlay_label(overlay: &str) -> &str {
    match overlay {
        "amodal" => "amodal outlines",
        other => other,
    }
}
