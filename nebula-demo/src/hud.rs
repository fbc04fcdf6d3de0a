//! The window's heads-up display: a few lines of text in the top-left
//! corner (frame time, chunks, triangles, jobs, LODs, altitude, speed, the
//! voxel under the crosshair), drawn with `wgpu_text` (glyph_brush) in
//! DejaVu Sans Mono (its licence: `assets/DejaVu-LICENSE.txt`).

use wgpu_text::glyph_brush::ab_glyph::FontRef;
use wgpu_text::glyph_brush::{Section, Text};
use wgpu_text::{BrushBuilder, TextBrush};

use nebula_render::context::GpuContext;
use nebula_render::overlay_pass;

/// The HUD's font.
const FONT: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");

/// Text drawn over the frame.
pub struct Hud {
    brush: TextBrush<FontRef<'static>>,
    text: String,
    /// Drawn at all (a key toggles it).
    pub visible: bool,
}

/// Why the HUD could not be made or drawn.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum HudError {
    /// The bundled font did not parse.
    #[error("the HUD font is not a font: {0}")]
    Font(String),
    /// The text could not be laid out into the glyph cache.
    #[error("laying out the HUD text failed: {0}")]
    Text(String),
}

impl Hud {
    /// A HUD for a `size` target of `format`.
    ///
    /// # Errors
    /// [`HudError::Font`] if the bundled font does not parse.
    pub fn new(gpu: &GpuContext, size: (u32, u32), format: wgpu::TextureFormat) -> Result<Self, HudError> {
        let builder = BrushBuilder::using_font_bytes(FONT).map_err(|e| HudError::Font(e.to_string()))?;
        Ok(Self { brush: builder.build(&gpu.device, size.0, size.1, format), text: String::new(), visible: true })
    }

    /// Follows a resized target.
    pub fn resize(&self, gpu: &GpuContext, size: (u32, u32)) {
        self.brush.resize_view(size.0 as f32, size.1 as f32, &gpu.queue);
    }

    /// The lines shown from now on.
    pub fn set_text(&mut self, text: String) {
        self.text = text;
    }

    /// Draws the text over `target` (its content kept), if visible.
    ///
    /// # Errors
    /// [`HudError::Text`] if the glyph cache cannot take the text.
    pub fn draw(&mut self, gpu: &GpuContext, target: &wgpu::TextureView) -> Result<(), HudError> {
        if !self.visible || self.text.is_empty() {
            return Ok(());
        }
        let section = Section::default()
            .add_text(Text::new(&self.text).with_scale(16.0).with_color([1.0, 1.0, 1.0, 0.9]))
            .with_screen_position((10.0, 8.0));
        self.brush.queue(&gpu.device, &gpu.queue, [&section]).map_err(|e| HudError::Text(e.to_string()))?;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("hud") });
        self.brush.draw(&mut overlay_pass(&mut encoder, target, "hud pass"));
        gpu.queue.submit([encoder.finish()]);
        Ok(())
    }
}
