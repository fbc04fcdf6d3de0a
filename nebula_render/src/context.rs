//! Opening a device for the renderer when the game has none yet (the demo,
//! tests, tools): an adapter that can present to a window's surface or
//! none, a device with the optional features the renderer uses, and the
//! limits of what it can draw.

use crate::renderer::{COLOR_FORMAT, RenderError, WANTED_FEATURES};

/// The instance options from the environment (wgpu's `WGPU_*` variables),
/// but for wgpu's validation of indirect draws, off unless
/// `WGPU_VALIDATION_INDIRECT_CALL` asks for it or on Windows. That
/// validation runs a compute pass over the frame's indirect draws before
/// the terrain pass and keeps a 33 MB buffer for it; the renderer writes
/// every indirect draw itself, from a live mesh's range in its page and an
/// instance in the frame's chunk table. On Windows the instance may open a
/// D3D12 adapter, where without it `instance_index` leaves out the draw's
/// first instance (the renderer's chunk table is read by it).
#[must_use]
pub fn instance_descriptor() -> wgpu::InstanceDescriptor {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    if cfg!(not(windows)) && std::env::var_os("WGPU_VALIDATION_INDIRECT_CALL").is_none() {
        descriptor.flags.remove(wgpu::InstanceFlags::VALIDATION_INDIRECT_CALL);
    }
    descriptor
}

/// Whether `adapter` rasterises on the CPU (lavapipe and other software
/// drivers): where a renderer leaves multisampling and occlusion culling
/// off by default (slower there, or no faster for more memory).
#[must_use]
pub fn is_cpu(adapter: &wgpu::Adapter) -> bool {
    adapter.get_info().device_type == wgpu::DeviceType::Cpu
}

/// An adapter with its device and queue.
pub struct GpuContext {
    /// The adapter.
    pub adapter: wgpu::Adapter,
    /// The device, with [`WANTED_FEATURES`] where the adapter has them.
    pub device: wgpu::Device,
    /// The queue.
    pub queue: wgpu::Queue,
    /// What the adapter says it is.
    pub adapter_name: String,
    /// The colour format to draw to: [`COLOR_FORMAT`] offscreen, else the
    /// surface's first non-sRGB format (the shader encodes sRGB itself).
    pub color_format: wgpu::TextureFormat,
}

impl GpuContext {
    /// Opens the first adapter wgpu offers (lavapipe on a machine with no
    /// GPU), one that can present to `surface` when given.
    ///
    /// # Errors
    /// [`RenderError::NoAdapter`] or [`RenderError::Device`].
    pub fn new(instance: &wgpu::Instance, surface: Option<&wgpu::Surface<'_>>) -> Result<Self, RenderError> {
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: surface,
            ..Default::default()
        }))
        .map_err(|e| RenderError::NoAdapter(e.to_string()))?;
        let adapter_name = adapter.get_info().name;
        let color_format = match surface {
            None => COLOR_FORMAT,
            Some(surface) => {
                let formats = surface.get_capabilities(&adapter).formats;
                formats.iter().copied().find(|f| !f.is_srgb()).or(formats.first().copied()).unwrap_or(COLOR_FORMAT)
            }
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("nebula device"),
            required_features: adapter.features() & WANTED_FEATURES,
            required_limits: wgpu::Limits::downlevel_defaults().using_resolution(adapter.limits()),
            // The renderer's buffers are few and large (mesh pages of 34 MB,
            // staging chunks of 8 MiB), so the allocator's small blocks waste
            // nothing; its default (`Performance`) blocks of 128–256 MB of
            // device memory and 64–128 MB of host memory held about 160 MB
            // unused in a 1 km/s flight on lavapipe, where both are the
            // process's own memory.
            memory_hints: wgpu::MemoryHints::MemoryUsage,
            ..Default::default()
        }))
        .map_err(|e| RenderError::Device(e.to_string()))?;
        Ok(Self { adapter, device, queue, adapter_name, color_format })
    }

    /// A device for offscreen work (no window).
    ///
    /// # Errors
    /// [`RenderError::NoAdapter`] when there is no adapter at all.
    pub fn headless() -> Result<Self, RenderError> {
        let instance = wgpu::Instance::new(instance_descriptor());
        Self::new(&instance, None)
    }

    /// A configuration for presenting to `surface` at `size` (clamped by
    /// [`Self::window_size`]).
    #[must_use]
    pub fn surface_config(&self, surface: &wgpu::Surface<'_>, size: (u32, u32)) -> Option<wgpu::SurfaceConfiguration> {
        let (width, height) = self.window_size(size);
        let mut config = surface.get_default_config(&self.adapter, width, height)?;
        config.format = self.color_format;
        config.present_mode = wgpu::PresentMode::AutoVsync;
        Some(config)
    }

    /// A window size this device can draw: each side clamped to 1 ..= its
    /// largest texture side (a larger window is drawn at the limit and
    /// stretched by the compositor).
    #[must_use]
    pub fn window_size(&self, (width, height): (u32, u32)) -> (u32, u32) {
        let side = self.device.limits().max_texture_dimension_2d;
        (width.clamp(1, side), height.clamp(1, side))
    }

    /// Checks that this device can draw a `size` image and read it back
    /// (its largest texture side and buffer), so a request past the
    /// limits is refused before any work, not as a panic inside wgpu.
    ///
    /// # Errors
    /// [`RenderError::TooLarge`] naming the limit.
    pub fn check_image_size(&self, (width, height): (u32, u32)) -> Result<(), RenderError> {
        let limits = self.device.limits();
        let too_large = |limit: String| Err(RenderError::TooLarge { width, height, limit });
        let side = limits.max_texture_dimension_2d;
        if width == 0 || height == 0 || width > side || height > side {
            return too_large(format!("each side must be 1 to {side} pixels"));
        }
        let row = u64::from(width * 4).div_ceil(u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT))
            * u64::from(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let bytes = row * u64::from(height);
        if bytes > limits.max_buffer_size {
            return too_large(format!(
                "its read-back buffer of {bytes} bytes passes the {} byte limit",
                limits.max_buffer_size
            ));
        }
        Ok(())
    }
}
