//! What every PNG plot of the project shares: its font, registered once, and the PNG writer
//! (`mole-plot`'s cost sweeps, `mole eval --plot`).

use plotters::style::FontStyle;
use std::path::Path;
use std::sync::Once;

/// The plots' font: DejaVu Sans Mono (assets/DejaVuSansMono-LICENSE.txt), so that drawing text
/// needs no system font library.
const FONT: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");

/// Registers [`FONT`] as plotters' `sans-serif`, once per process; call before drawing text.
pub fn register_font() {
    static FONT_REGISTERED: Once = Once::new();
    FONT_REGISTERED.call_once(|| {
        // The font is ours and parses; a failure would leave the text out, not the lines.
        _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

/// Writes an RGB buffer of `(width, height)` to `path` as a PNG.
pub fn write_png(path: &Path, (width, height): (u32, u32), pixels: &[u8]) -> Result<(), String> {
    let failed = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    let file = std::fs::File::create(path).map_err(|e| failed(&e))?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| failed(&e))?;
    writer.write_image_data(pixels).map_err(|e| failed(&e))
}
