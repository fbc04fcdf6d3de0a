//! An offscreen colour target read back to the CPU: headless pictures,
//! screenshots, image tests.

use crate::context::GpuContext;
use crate::renderer::{COLOR_FORMAT, RenderError};

/// An offscreen colour target and the buffer it is read back through.
pub struct Offscreen {
    texture: wgpu::Texture,
    /// View to draw into.
    pub view: wgpu::TextureView,
    size: (u32, u32),
}

impl Offscreen {
    /// A `width` × `height` target.
    ///
    /// # Errors
    /// [`RenderError::TooLarge`] past the device's limits
    /// ([`GpuContext::check_image_size`]).
    pub fn new(gpu: &GpuContext, size: (u32, u32)) -> Result<Self, RenderError> {
        gpu.check_image_size(size)?;
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen colour"),
            size: wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: COLOR_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        Ok(Self { texture, view, size })
    }

    /// The image size.
    #[must_use]
    pub fn size(&self) -> (u32, u32) {
        self.size
    }

    /// Copies the image back: RGBA8, row 0 at the top, no row padding.
    ///
    /// # Errors
    /// [`RenderError::Readback`] if mapping fails.
    pub fn read(&self, gpu: &GpuContext) -> Result<Vec<u8>, RenderError> {
        read_texture(&gpu.device, &gpu.queue, &self.texture, self.size, wgpu::TextureAspect::All, 4)
    }
}

/// Copies `texture`'s `aspect` (`size`, `bytes_per_pixel` bytes a pixel)
/// back to the CPU and waits for it: row 0 at the top, no row padding.
pub(crate) fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    (width, height): (u32, u32),
    aspect: wgpu::TextureAspect,
    bytes_per_pixel: u32,
) -> Result<Vec<u8>, RenderError> {
    let unpadded = width * bytes_per_pixel;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let padded = unpadded.div_ceil(align) * align;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back"),
        size: u64::from(padded) * u64::from(height),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("read-back") });
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo { texture, mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    queue.submit([encoder.finish()]);
    map_and_wait(device, &buffer)?;
    let mut pixels = Vec::with_capacity((unpadded * height) as usize);
    {
        let mapped = buffer.get_mapped_range(..).map_err(|e| RenderError::Readback(e.to_string()))?;
        for row in mapped.chunks_exact(padded as usize) {
            pixels.extend_from_slice(&row[..unpadded as usize]);
        }
    }
    buffer.unmap();
    Ok(pixels)
}

/// Copies the first `bytes` of `source` (a `COPY_SRC` buffer) back to the
/// CPU and waits for it.
pub(crate) fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    source: &wgpu::Buffer,
    bytes: u64,
) -> Result<Vec<u8>, RenderError> {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back"),
        size: bytes,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("read-back") });
    encoder.copy_buffer_to_buffer(source, 0, &buffer, 0, bytes);
    queue.submit([encoder.finish()]);
    map_and_wait(device, &buffer)?;
    let copy = buffer.get_mapped_range(..).map_err(|e| RenderError::Readback(e.to_string()))?.to_vec();
    buffer.unmap();
    Ok(copy)
}

/// Maps `buffer` for reading once the work submitted so far is done, and
/// waits for it.
fn map_and_wait(device: &wgpu::Device, buffer: &wgpu::Buffer) -> Result<(), RenderError> {
    let (sender, receiver) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |result| {
        let _ = sender.send(result);
    });
    device
        .poll(wgpu::PollType::Wait { submission_index: None, timeout: None })
        .map_err(|e| RenderError::Readback(e.to_string()))?;
    receiver.recv().map_err(|e| RenderError::Readback(e.to_string()))?.map_err(|e| RenderError::Readback(e.to_string()))
}
