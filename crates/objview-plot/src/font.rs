//! The one font of every figure: DejaVu Sans, compiled into the crate (`assets/`, license in
//! `assets/LICENSE-DejaVu.txt`) and registered with plotters' ab_glyph text renderer.
//!
//! Why embedded: plotters' default text path looks fonts up through the system (fontconfig),
//! which CI machines and containers often lack, and whose answer differs between machines. With
//! the font inside the binary, PNG text is rasterized the same way everywhere, which is what makes
//! the figures byte-reproducible. SVG files name the generic family `sans-serif`; their text is
//! laid out with this font's metrics and displayed with the viewer's sans-serif font.

use std::sync::OnceLock;

use plotters::style::{register_font, FontStyle};

use crate::PlotError;

/// The font family name charts use (plotters' `FontFamily::SansSerif`). The embedded font is
/// registered under it, so that SVG output carries a family every viewer knows.
pub const FAMILY: &str = "sans-serif";

/// What is embedded, for the provenance block of figure outputs.
pub const FONT_DESCRIPTION: &str = "DejaVu Sans 2.37 (embedded; Bitstream Vera / Arev font licenses)";

static DEJAVU_SANS: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

static REGISTERED: OnceLock<Result<(), String>> = OnceLock::new();

/// Registers the embedded font (once per process); every drawing entry point calls this first.
pub fn ensure_registered() -> Result<(), PlotError> {
    REGISTERED
        .get_or_init(|| {
            register_font(FAMILY, FontStyle::Normal, DEJAVU_SANS)
                .map_err(|_| "not a valid TrueType/OpenType font".to_string())
        })
        .clone()
        .map_err(|reason| PlotError::Font { name: "DejaVuSans.ttf", reason })
}

/// The embedded font for direct rasterization (the PNG backend's text, [`crate::png_text`]).
pub fn font_ref() -> Result<ab_glyph::FontRef<'static>, PlotError> {
    ab_glyph::FontRef::try_from_slice(DEJAVU_SANS)
        .map_err(|e| PlotError::Font { name: "DejaVuSans.ttf", reason: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn embedded_font_registers_and_is_the_dejavu_file() {
        ensure_registered().unwrap();
        ensure_registered().unwrap();
        font_ref().unwrap();
        // TrueType magic and the family name inside the name table.
        assert_eq!(&DEJAVU_SANS[..4], &[0, 1, 0, 0]);
        assert!(DEJAVU_SANS.windows(11).any(|w| w == b"DejaVu Sans"));
    }
}
