//! The PNG drawing backend: plotters' bitmap backend with its own text rasterizer.
//!
//! Why: plotters 0.3.7's ab_glyph text path places each glyph at the pen position without the
//! glyph's side bearing and truncates the pen to whole pixels, so letters with a negative
//! bearing drift right ("ob jects") and spacing looks uneven. [`PngBackend`] forwards every
//! drawing call to [`BitMapBackend`] except `draw_text`, which lays the string out with the
//! same advances and kerning as plotters' size estimate (so label areas still fit) but puts
//! every glyph at its exact outline bounds on a common baseline. Anchoring and rotation follow
//! plotters' default `draw_text`, so the picture matches the SVG output.

use ab_glyph::{point, Font, FontRef, PxScale, ScaleFont};
use plotters::prelude::BitMapBackend;
use plotters_backend::text_anchor::{HPos, VPos};
use plotters_backend::{
    BackendColor, BackendCoord, BackendStyle, BackendTextStyle, DrawingBackend, DrawingErrorKind,
};

/// Height of plotters' text layout box per unit of font size (its ab_glyph estimate: size/1.24).
const LAYOUT_HEIGHT_PER_SIZE: f64 = 1.0 / 1.24;

/// [`BitMapBackend`] with a glyph-exact `draw_text` (see the module docs).
pub struct PngBackend<'a> {
    inner: BitMapBackend<'a>,
    font: FontRef<'static>,
}

impl<'a> PngBackend<'a> {
    /// Draws into `rgb` (width·height·3 bytes) with text in `font`.
    pub fn new(rgb: &'a mut [u8], size: (u32, u32), font: FontRef<'static>) -> Self {
        PngBackend { inner: BitMapBackend::with_buffer(rgb, size), font }
    }
}

type Res<E> = Result<(), DrawingErrorKind<E>>;
type BitMapError = <BitMapBackend<'static> as DrawingBackend>::ErrorType;

impl DrawingBackend for PngBackend<'_> {
    type ErrorType = BitMapError;

    fn get_size(&self) -> (u32, u32) {
        self.inner.get_size()
    }

    fn ensure_prepared(&mut self) -> Res<Self::ErrorType> {
        self.inner.ensure_prepared()
    }

    fn present(&mut self) -> Res<Self::ErrorType> {
        self.inner.present()
    }

    fn draw_pixel(&mut self, point: BackendCoord, color: BackendColor) -> Res<Self::ErrorType> {
        self.inner.draw_pixel(point, color)
    }

    fn draw_line<S: BackendStyle>(
        &mut self,
        from: BackendCoord,
        to: BackendCoord,
        style: &S,
    ) -> Res<Self::ErrorType> {
        self.inner.draw_line(from, to, style)
    }

    fn draw_rect<S: BackendStyle>(
        &mut self,
        upper_left: BackendCoord,
        bottom_right: BackendCoord,
        style: &S,
        fill: bool,
    ) -> Res<Self::ErrorType> {
        self.inner.draw_rect(upper_left, bottom_right, style, fill)
    }

    fn draw_path<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        path: I,
        style: &S,
    ) -> Res<Self::ErrorType> {
        self.inner.draw_path(path, style)
    }

    fn draw_circle<S: BackendStyle>(
        &mut self,
        center: BackendCoord,
        radius: u32,
        style: &S,
        fill: bool,
    ) -> Res<Self::ErrorType> {
        self.inner.draw_circle(center, radius, style, fill)
    }

    fn fill_polygon<S: BackendStyle, I: IntoIterator<Item = BackendCoord>>(
        &mut self,
        vert: I,
        style: &S,
    ) -> Res<Self::ErrorType> {
        self.inner.fill_polygon(vert, style)
    }

    fn estimate_text_size<TStyle: BackendTextStyle>(
        &self,
        text: &str,
        style: &TStyle,
    ) -> Result<(u32, u32), DrawingErrorKind<Self::ErrorType>> {
        self.inner.estimate_text_size(text, style)
    }

    fn blit_bitmap(&mut self, pos: BackendCoord, size: (u32, u32), src: &[u8]) -> Res<Self::ErrorType> {
        self.inner.blit_bitmap(pos, size, src)
    }

    fn draw_text<TStyle: BackendTextStyle>(
        &mut self,
        text: &str,
        style: &TStyle,
        pos: BackendCoord,
    ) -> Res<Self::ErrorType> {
        let color = style.color();
        if color.alpha == 0.0 {
            return Ok(());
        }
        let scale = PxScale::from(style.size() as f32);
        let scaled = self.font.as_scaled(scale);
        // Pen positions: advances and kerning exactly as plotters' width estimate.
        let mut pen = 0f32;
        let mut prev = None;
        let mut glyphs = Vec::with_capacity(text.len());
        for c in text.chars() {
            let id = scaled.glyph_id(c);
            if let Some(p) = prev {
                pen += scaled.kern(p, id);
            }
            glyphs.push((id, pen));
            pen += scaled.h_advance(id);
            prev = Some(id);
        }
        let width = pen as i32;
        let height = (style.size() * LAYOUT_HEIGHT_PER_SIZE) as i32;
        let anchor = style.anchor();
        let dx = match anchor.h_pos {
            HPos::Left => 0,
            HPos::Right => -width,
            HPos::Center => -width / 2,
        };
        let dy = match anchor.v_pos {
            VPos::Top => 0,
            VPos::Center => -height / 2,
            VPos::Bottom => -height,
        };
        // The baseline splits the layout box in the font's ascent : descent ratio.
        let (ascent, descent) = (scaled.ascent(), scaled.descent());
        let baseline = height as f32 * ascent / (ascent - descent);
        let transform = style.transform();
        let (w, h) = self.inner.get_size();
        let PngBackend { inner, font } = self;
        for (id, x) in glyphs {
            let Some(outline) = font.outline_glyph(id.with_scale_and_position(scale, point(x, baseline)))
            else {
                continue;
            };
            let bounds = outline.px_bounds();
            let (ox, oy) = (bounds.min.x as i32 + dx, bounds.min.y as i32 + dy);
            let mut failure = None;
            outline.draw(|gx, gy, coverage| {
                if failure.is_some() || coverage <= 0.0 {
                    return;
                }
                let (x, y) = transform.transform(ox + gx as i32, oy + gy as i32);
                let (x, y) = (pos.0 + x, pos.1 + y);
                if x >= 0 && y >= 0 && x < w as i32 && y < h as i32 {
                    let c =
                        BackendColor { alpha: color.alpha * f64::from(coverage.min(1.0)), rgb: color.rgb };
                    if let Err(e) = inner.draw_pixel((x, y), c) {
                        failure = Some(e);
                    }
                }
            });
            if let Some(e) = failure {
                return Err(e);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::font;
    use plotters::prelude::*;
    use plotters::style::text_anchor::Pos;

    /// Bounding box (x0, y0, x1, y1) of the dark pixels of an RGB buffer.
    fn ink(rgb: &[u8], w: usize) -> (usize, usize, usize, usize) {
        let mut b = (usize::MAX, usize::MAX, 0, 0);
        for (i, p) in rgb.chunks(3).enumerate() {
            if p.iter().all(|&c| c < 128) {
                let (x, y) = (i % w, i / w);
                b = (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y));
            }
        }
        b
    }

    fn render(text: &str, rotate: bool, px: f64) -> ((usize, usize, usize, usize), (u32, u32)) {
        font::ensure_registered().unwrap();
        let (w, h) = (400u32, 400u32);
        let mut rgb = vec![0u8; (w * h * 3) as usize];
        let size;
        {
            let root = PngBackend::new(&mut rgb, (w, h), font::font_ref().unwrap()).into_drawing_area();
            root.fill(&WHITE).unwrap();
            let mut style =
                TextStyle::from((font::FAMILY, px).into_font()).pos(Pos::new(HPos::Left, VPos::Top));
            if rotate {
                style = style.transform(FontTransform::Rotate270);
            }
            size = root.estimate_text_size(text, &style).unwrap();
            root.draw(&Text::new(text, (100, 300), style)).unwrap();
            root.present().unwrap();
        }
        (ink(&rgb, w as usize), size)
    }

    #[test]
    fn text_ink_stays_in_plotters_layout_box() {
        // Horizontal: the box is (100, 300) .. (100 + width, 300 + height); glyphs may overhang
        // by a pixel or two (bearing, descender below the nominal box).
        let ((x0, y0, x1, y1), (tw, th)) = render("objects (count) jpg", false, 30.0);
        let (tw, th) = (tw as usize, th as usize);
        assert!((99..=104).contains(&x0), "ink starts at x {x0}");
        assert!(x1 <= 100 + tw + 2 && x1 + 6 >= 100 + tw, "ink ends at x {x1}, width {tw}");
        assert!(y0 >= 299 && y1 <= 300 + th + 8, "ink rows {y0}..{y1}, height {th}");
        // Rotated 270°: the same box turned counter-clockwise about the anchor, going up.
        let ((x0, y0, x1, y1), _) = render("objects (count) jpg", true, 30.0);
        assert!(
            y1 <= 301 && y1 + 6 >= 300 && y0 + 2 >= 300 - tw && y0 <= 300 - tw + 6,
            "ink rows {y0}..{y1}, width {tw}"
        );
        assert!(x0 >= 99 && x1 <= 100 + th + 8, "ink columns {x0}..{x1}");
    }

    #[test]
    fn glyphs_start_at_their_outline_bounds() {
        // Each glyph's ink starts at pen + its left side bearing (plotters' own path drops the
        // bearing: an 'l' would start right at the anchor). Checked at 100 px where bearings are
        // several pixels.
        let font = font::font_ref().unwrap();
        for c in ['l', 'j', 'A', 'o'] {
            let ((x0, ..), _) = render(&c.to_string(), false, 100.0);
            let glyph = font.glyph_id(c).with_scale_and_position(PxScale::from(100.0), point(0.0, 0.0));
            let min_x = font.outline_glyph(glyph).unwrap().px_bounds().min.x as i64;
            let got = x0 as i64 - 100;
            assert!(
                (got - min_x).abs() <= 1,
                "'{c}': ink starts {got} px from the anchor, outline at {min_x}"
            );
        }
        let ((x0, ..), _) = render("l", false, 100.0);
        assert!(x0 >= 105, "'l' has a visible left bearing at 100 px");
    }
}
