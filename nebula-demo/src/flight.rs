//! Headless flights: a camera path from keyframes, rendered frame by frame
//! in real time with meshing running on its own threads, every frame
//! checked for cracks.
//!
//! ```text
//!   [{"t": 0, "pos": [x, y, z], "look_at": [x, y, z], "up": [x, y, z]}, …]
//! ```
//!
//! `t` in seconds, increasing; `up` optional (default: radial up at the
//! eye). Position, look-at and up are interpolated linearly between
//! keyframes. Frame `k` shows flight time `k / fps` and is drawn no earlier
//! than `k / fps` seconds of wall time after the first frame; the renderer
//! never waits for meshing, so a frame shows whatever is meshed by then.

use std::path::Path;
use std::time::Instant;

use nebula_math::DVec3;

use crate::app::PlanetApp;
use crate::headless::{Figures, Shot, draw_into, prime, shot_view, write_png};

/// A bad flight file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FlightError {
    /// Not JSON.
    #[error("flight is not JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// Not a non-empty array of keyframe objects.
    #[error("flight must be a non-empty JSON array of keyframes, got {0}")]
    NotAnArray(String),
    /// A keyframe lacks a field or has one of the wrong shape.
    #[error("keyframe {index}: {problem}")]
    BadKeyframe {
        /// Which keyframe (0-based).
        index: usize,
        /// What is wrong.
        problem: String,
    },
    /// Times that do not increase.
    #[error("keyframe {index}: time {time} s is not after the previous keyframe's {previous} s")]
    TimeNotIncreasing {
        /// Which keyframe.
        index: usize,
        /// Its time.
        time: f64,
        /// The previous keyframe's time.
        previous: f64,
    },
}

/// One keyframe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keyframe {
    /// Seconds from the start.
    pub t: f64,
    /// Eye, metres, planet centre at the origin.
    pub pos: DVec3,
    /// Point looked at.
    pub look_at: DVec3,
    /// Up, if given.
    pub up: Option<DVec3>,
}

/// A checked camera path.
#[derive(Clone, Debug, PartialEq)]
pub struct Flight {
    keys: Vec<Keyframe>,
}

impl Flight {
    /// Parses and checks a flight file's text.
    ///
    /// # Errors
    /// [`FlightError`] naming the keyframe and field at fault.
    pub fn from_json(text: &str) -> Result<Self, FlightError> {
        let value: serde_json::Value = serde_json::from_str(text)?;
        let items = value.as_array().filter(|a| !a.is_empty()).ok_or_else(|| {
            let mut shown = value.to_string();
            shown.truncate(60);
            FlightError::NotAnArray(shown)
        })?;
        let mut keys = Vec::with_capacity(items.len());
        for (index, item) in items.iter().enumerate() {
            let bad = |problem: String| FlightError::BadKeyframe { index, problem };
            let number = |name: &str| -> Result<f64, FlightError> {
                let v = item.get(name).ok_or_else(|| bad(format!("missing \"{name}\"")))?;
                v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| bad(format!("\"{name}\" must be a finite number")))
            };
            let vector = |name: &str| -> Result<Option<DVec3>, FlightError> {
                let Some(v) = item.get(name) else { return Ok(None) };
                let parts: Option<Vec<f64>> =
                    v.as_array().and_then(|a| a.iter().map(|x| x.as_f64().filter(|x| x.is_finite())).collect());
                match parts.as_deref() {
                    Some([x, y, z]) => Ok(Some(DVec3::new(*x, *y, *z))),
                    _ => Err(bad(format!("\"{name}\" must be [x, y, z] of finite numbers"))),
                }
            };
            let t = number("t")?;
            let pos = vector("pos")?.ok_or_else(|| bad("missing \"pos\"".into()))?;
            let look_at = vector("look_at")?.ok_or_else(|| bad("missing \"look_at\"".into()))?;
            keys.push(Keyframe { t, pos, look_at, up: vector("up")? });
        }
        Self::from_keyframes(keys)
    }

    /// A flight from keyframes made in code, checked as a file's would be.
    ///
    /// # Errors
    /// [`FlightError`] for no keyframes, times that do not increase, or
    /// non-finite values.
    pub fn from_keyframes(keys: Vec<Keyframe>) -> Result<Self, FlightError> {
        if keys.is_empty() {
            return Err(FlightError::NotAnArray("[]".into()));
        }
        for (index, key) in keys.iter().enumerate() {
            let finite = key.t.is_finite()
                && key.pos.is_finite()
                && key.look_at.is_finite()
                && key.up.is_none_or(|u| u.is_finite());
            if !finite {
                return Err(FlightError::BadKeyframe { index, problem: "a value is not finite".into() });
            }
            if index > 0 && key.t <= keys[index - 1].t {
                return Err(FlightError::TimeNotIncreasing { index, time: key.t, previous: keys[index - 1].t });
            }
        }
        Ok(Self { keys })
    }

    /// The keyframes.
    #[must_use]
    pub fn keyframes(&self) -> &[Keyframe] {
        &self.keys
    }

    /// Time of the last keyframe, seconds.
    #[must_use]
    pub fn duration(&self) -> f64 {
        self.keys.last().map_or(0.0, |k| k.t)
    }

    /// The camera at `t` seconds (clamped to the path), linearly
    /// interpolated.
    #[must_use]
    pub fn pose(&self, t: f64) -> Keyframe {
        let i = self.keys.partition_point(|k| k.t <= t);
        if i == 0 {
            return Keyframe { t, ..self.keys[0] };
        }
        if i == self.keys.len() {
            return Keyframe { t, ..self.keys[i - 1] };
        }
        let (a, b) = (self.keys[i - 1], self.keys[i]);
        let s = (t - a.t) / (b.t - a.t);
        let up = match (a.up, b.up) {
            (Some(u), Some(v)) => Some(lerp(u, v, s)),
            (u, v) => u.or(v),
        };
        Keyframe { t, pos: lerp(a.pos, b.pos, s), look_at: lerp(a.look_at, b.look_at, s), up }
    }
}

/// `a + (b − a)·s`: between equal keyframes the keyframe itself, bit for
/// bit, as a camera held still is (glam's `lerp`, `a·(1 − s) + b·s`, moved
/// it by its last bits every frame, and a still camera's plans were made
/// anew each frame for it).
fn lerp(a: DVec3, b: DVec3, s: f64) -> DVec3 {
    a + (b - a) * s
}

/// One rendered frame of a flight.
#[derive(Clone, Debug)]
pub struct FlightFrame {
    /// Flight time, seconds.
    pub time_s: f64,
    /// Wall time after the first frame when it was drawn, seconds.
    pub wall_s: f64,
    /// The frame's figures (cracks, chunks, jobs).
    pub figures: Figures,
    /// Milliseconds the systems' step took (LOD, uploads, selection).
    pub step_ms: f64,
    /// CPU milliseconds the frame thread spent in that step: `step_ms`
    /// less the time it waited for a core (the meshing threads and a
    /// software rasteriser share them on a small machine).
    pub step_cpu_ms: f64,
}

/// What a flight showed.
#[derive(Clone, Debug)]
pub struct FlightReport {
    /// Every frame.
    pub frames: Vec<FlightFrame>,
    /// Milliseconds before the first frame could be drawn complete.
    pub first_frame_ms: f64,
    /// The adapter.
    pub adapter: String,
    /// Frames whose LOD tree was made ahead on the LOD thread, and frames
    /// whose tree made ahead could not serve
    /// (`Streamer::lod_thread_frames`).
    pub lod_thread_frames: (u64, u64),
    /// Frames that drew the plan before while the LOD thread made the next
    /// (`Streamer::frames_drawn_while_planning`).
    pub frames_drawn_while_planning: u64,
}

impl FlightReport {
    /// The frame with the most crack pixels (the first of equals).
    #[must_use]
    pub fn worst_frame(&self) -> Option<(usize, &FlightFrame)> {
        self.frames
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.figures.crack_pixels.cmp(&b.1.figures.crack_pixels).then(b.0.cmp(&a.0)))
    }

    /// Median, 95th percentile and largest of a per-frame figure over the
    /// frames that have it (`null` where none has).
    fn spread(&self, figure: impl Fn(&FlightFrame) -> Option<f64>) -> serde_json::Value {
        let mut values: Vec<f64> = self.frames.iter().filter_map(figure).collect();
        values.sort_by(f64::total_cmp);
        let at = |q: f64| values.get(((values.len() as f64 * q) as usize).min(values.len().saturating_sub(1)));
        match values.last() {
            Some(max) => serde_json::json!({ "median": at(0.5), "p95": at(0.95), "max": max }),
            None => serde_json::Value::Null,
        }
    }

    /// The report as JSON: per frame time, crack pixels, chunks drawn,
    /// jobs in flight, the frame's CPU and GPU figures; their spread over
    /// the flight; the worst frame; the process's peak memory.
    #[must_use]
    pub fn json(&self) -> serde_json::Value {
        let frames: Vec<serde_json::Value> = self
            .frames
            .iter()
            .map(|f| {
                serde_json::json!({
                    "time_s": f.time_s,
                    "wall_s": f.wall_s,
                    "crack_pixels": f.figures.crack_pixels,
                    "crack_pixels_sphere_rule": f.figures.cracks.sphere_cracks,
                    "crack_pixels_geometry_rule": f.figures.cracks.geometry_cracks,
                    "crack_samples": f.figures.cracks.samples,
                    "chunks": f.figures.frame.chunks,
                    "triangles": f.figures.frame.triangles,
                    "rasterised_triangles": f.figures.culling.map(|c| c.triangles()),
                    "skirt_triangles": f.figures.frame.skirt_triangles,
                    "unsettled": f.figures.frame.unsettled,
                    "stand_ins": f.figures.frame.stand_ins,
                    "backstops": f.figures.frame.backstops,
                    "max_stand_in_levels": f.figures.frame.max_stand_in_levels,
                    "jobs_in_flight": f.figures.frame.jobs_in_flight,
                    "prefetch_jobs": f.figures.frame.prefetch_jobs,
                    "step_ms": f.step_ms,
                    "step_cpu_ms": f.step_cpu_ms,
                    "lod_ms": f.figures.frame.times.lod_ms,
                    "upload_ms": f.figures.frame.times.upload_ms,
                    "select_ms": f.figures.frame.times.select_ms,
                    "plan_ms": f.figures.frame.times.plan_ms,
                    "planned_ahead": f.figures.frame.times.planned_ahead,
                    "lod_wait_ms": f.figures.frame.times.lod_wait_ms,
                    "upload_bytes": f.figures.frame.times.upload_bytes,
                    "gpu_mesh_bytes": f.figures.frame.renderer_bytes,
                    "gpu_mesh_buffer_bytes": f.figures.gpu_buffer_bytes,
                    "draw_ms": f.figures.draw_ms,
                    "encode_ms": f.figures.render.encode_ms,
                    "draw_calls": f.figures.render.draw_calls,
                    "gpu_ms": f.figures.render.gpu_ms,
                    "check_ms": f.figures.check_ms,
                })
            })
            .collect();
        let worst = self.worst_frame().map(
            |(i, f)| serde_json::json!({ "frame": i, "time_s": f.time_s, "crack_pixels": f.figures.crack_pixels }),
        );
        let coarsest = self.frames.iter().map(|f| f.figures.frame.max_stand_in_levels).max();
        serde_json::json!({
            "adapter": self.adapter,
            "first_frame_ms": self.first_frame_ms,
            "peak_rss_bytes": crate::headless::peak_rss_bytes(),
            "lod_thread_frames": { "made_ahead": self.lod_thread_frames.0, "missed": self.lod_thread_frames.1 },
            "planned_ahead_frames": self.frames.iter().filter(|f| f.figures.frame.times.planned_ahead).count(),
            "frames_drawn_while_planning": self.frames_drawn_while_planning,
            "summary": {
                "step_ms": self.spread(|f| Some(f.step_ms)),
                // The whole frame on the frame thread, one at a time: its
                // step and its draw, waited for (1000 / frame_ms is the
                // frame rate where nothing is read back; with frames
                // written or crack-checked it includes the read-back).
                "frame_ms": self.spread(|f| Some(f.step_ms + f.figures.draw_ms)),
                "step_cpu_ms": self.spread(|f| Some(f.step_cpu_ms)),
                "lod_ms": self.spread(|f| Some(f.figures.frame.times.lod_ms)),
                "upload_ms": self.spread(|f| Some(f.figures.frame.times.upload_ms)),
                "select_ms": self.spread(|f| Some(f.figures.frame.times.select_ms)),
                // Planning the selection, on the LOD thread when made ahead.
                "plan_ms": self.spread(|f| Some(f.figures.frame.times.plan_ms)),
                "encode_ms": self.spread(|f| Some(f.figures.render.encode_ms)),
                "gpu_ms": self.spread(|f| f.figures.render.gpu_ms),
                "draw_calls": self.spread(|f| Some(f64::from(f.figures.render.draw_calls))),
                "chunks": self.spread(|f| Some(f.figures.frame.chunks as f64)),
                "triangles": self.spread(|f| Some(f.figures.frame.triangles as f64)),
                // After occlusion culling (surfaces and skirts).
                "rasterised_triangles": self.spread(|f| f.figures.culling.map(|c| c.triangles() as f64)),
                "skirt_triangles": self.spread(|f| Some(f.figures.frame.skirt_triangles as f64)),
                "unsettled": self.spread(|f| Some(f.figures.frame.unsettled as f64)),
                "upload_bytes": self.spread(|f| Some(f.figures.frame.times.upload_bytes as f64)),
            },
            "max_stand_in_levels": coarsest,
            "chunks_meshed": self.frames.last().map(|f| f.figures.frame.times.chunks_meshed),
            "chunks_remeshed_for_seams": self.frames.last().map(|f| f.figures.frame.times.chunks_remeshed),
            "frame_count": self.frames.len(),
            "worst_frame": worst,
            "frames": frames,
        })
    }
}

/// The most frames a flight may have.
pub const MAX_FLIGHT_FRAMES: usize = 5_184_000;

/// Flies `flight` at `fps` frames per second with `template`'s size, field
/// of view, background and debug view; writes `DIR/00000.png`, … when
/// `frames_dir` is given. With a background every frame's cracks are
/// counted. Frames neither written nor checked are not read back: each is
/// drawn into the same target and waited for, so `frame_ms` is what a
/// game's frame would cost.
///
/// # Errors
/// A keyframe camera that is unusable (NaN direction, inside the planet),
/// a bad `fps`, read-back or PNG failures.
pub fn fly(
    app: &mut PlanetApp,
    flight: &Flight,
    template: &Shot,
    fps: f64,
    frames_dir: Option<&Path>,
) -> anyhow::Result<FlightReport> {
    anyhow::ensure!(fps.is_finite() && fps > 0.0 && fps <= 1000.0, "--fps must be in (0, 1000], got {fps}");
    app.gpu().check_image_size(template.size)?;
    let shot_at = |t: f64| {
        let pose = flight.pose(t);
        Shot { position: pose.pos, look_at: pose.look_at, up: pose.up, ..template.clone() }
    };
    let min_radius = app.min_surface_radius();
    for key in flight.keyframes() {
        shot_view(&shot_at(key.t))?;
        anyhow::ensure!(
            key.pos.length() > min_radius,
            "keyframe at {} s is inside the planet ({:.1} m from the centre, solid below {:.1} m)",
            key.t,
            key.pos.length(),
            min_radius
        );
    }
    app.keep_cpu_meshes(template.background.is_some());
    app.set_view(shot_view(&shot_at(0.0))?);
    // The sun stays where the first pose places it.
    crate::headless::place_sun(app, &shot_at(0.0))?;
    let first_frame_ms = prime(app)?;
    // A frame list that fits in memory (a day at 60 fps); a keyframe at
    // t = 1e20 s is refused, not an overflow.
    let frames = (flight.duration() * fps).floor();
    anyhow::ensure!(
        frames <= MAX_FLIGHT_FRAMES as f64,
        "the flight is {frames} frames long at {fps} fps; at most {MAX_FLIGHT_FRAMES} are flown"
    );
    let count = frames as usize + 1;
    let mut frames = Vec::with_capacity(count);
    // Frames are read back only when written or crack-checked: else each
    // is drawn into one target and waited for, as a game's would be.
    let read_back = frames_dir.is_some() || template.background.is_some();
    let target = nebula_render::readback::Offscreen::new(app.gpu(), template.size)?;
    let start = Instant::now();
    for k in 0..count {
        let time_s = k as f64 / fps;
        // Never earlier than its time; late if drawing and checking are slow.
        let due = std::time::Duration::from_secs_f64(time_s);
        if let Some(wait) = due.checked_sub(start.elapsed()) {
            std::thread::sleep(wait);
        }
        let shot = shot_at(time_s);
        let view = shot_view(&shot)?;
        app.set_view(view);
        let (stepped, stepped_cpu) = (Instant::now(), cpu_time::ThreadTime::now());
        app.step();
        let step_ms = stepped.elapsed().as_secs_f64() * 1e3;
        let step_cpu_ms = stepped_cpu.elapsed().as_secs_f64() * 1e3;
        let wall_s = start.elapsed().as_secs_f64();
        let picture = draw_into(app, &shot, &view, &target, read_back)?;
        if let Some(dir) = frames_dir {
            write_png(&dir.join(format!("{k:05}.png")), &picture.rgba, picture.size)?;
        }
        frames.push(FlightFrame { time_s, wall_s, figures: picture.figures, step_ms, step_cpu_ms });
    }
    Ok(FlightReport {
        frames,
        first_frame_ms,
        adapter: app.gpu().adapter_name.clone(),
        lod_thread_frames: app.streamer().lod_thread_frames(),
        frames_drawn_while_planning: app.streamer().frames_drawn_while_planning(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The summary's median and 95th percentile are the flight's, taken
    /// over the frames that have the figure.
    #[test]
    fn the_summary_spreads_each_figure_over_the_frames() {
        let frame = |step_ms: f64, gpu_ms: Option<f64>| {
            let mut figures = Figures::default();
            figures.render.gpu_ms = gpu_ms;
            figures.draw_ms = 1.0;
            FlightFrame { time_s: 0.0, wall_s: 0.0, figures, step_ms, step_cpu_ms: step_ms }
        };
        let frames = (1..=20).map(|n| frame(f64::from(n), (n > 10).then_some(2.0 * f64::from(n)))).collect();
        let report = FlightReport {
            frames,
            first_frame_ms: 0.0,
            adapter: String::new(),
            lod_thread_frames: (0, 0),
            frames_drawn_while_planning: 0,
        };
        let summary = &report.json()["summary"];
        assert_eq!(summary["step_ms"], serde_json::json!({ "median": 11.0, "p95": 20.0, "max": 20.0 }));
        assert_eq!(summary["gpu_ms"], serde_json::json!({ "median": 32.0, "p95": 40.0, "max": 40.0 }));
        assert_eq!(summary["frame_ms"], serde_json::json!({ "median": 12.0, "p95": 21.0, "max": 21.0 }));
        let empty = FlightReport {
            frames: Vec::new(),
            first_frame_ms: 0.0,
            adapter: String::new(),
            lod_thread_frames: (0, 0),
            frames_drawn_while_planning: 0,
        };
        assert!(empty.json()["summary"]["step_ms"].is_null());
    }

    #[test]
    fn keyframes_parse_interpolate_and_refuse_bad_input() {
        let flight = Flight::from_json(
            r#"[{"t": 0, "pos": [0, 0, 10], "look_at": [0, 0, 0]},
                {"t": 2, "pos": [4, 0, 10], "look_at": [2, 0, 0], "up": [0, 1, 0]}]"#,
        )
        .expect("valid");
        assert_eq!(flight.duration(), 2.0);
        let mid = flight.pose(0.5);
        assert_eq!(mid.pos, DVec3::new(1.0, 0.0, 10.0));
        assert_eq!(mid.look_at, DVec3::new(0.5, 0.0, 0.0));
        assert_eq!(mid.up, Some(DVec3::Y), "one side's up stands for both");
        assert_eq!(flight.pose(9.0).pos, DVec3::new(4.0, 0.0, 10.0), "clamped");
        assert_eq!(flight.pose(-1.0).pos, DVec3::new(0.0, 0.0, 10.0), "clamped");
        // A hold between equal keyframes at Earth coordinates is the
        // keyframe bit for bit all through (a still camera's plans are
        // reused only for the same camera); glam's lerp is not.
        let at = DVec3::new(6_218_042.78, 1_243_608.56, 621_804.28);
        let key =
            |t: f64| format!(r#"{{"t": {t}, "pos": [{:?}, {:?}, {:?}], "look_at": [0, 0, 0]}}"#, at.x, at.y, at.z);
        let hold = Flight::from_json(&format!("[{}, {}]", key(0.0), key(25.0))).expect("valid");
        assert!((0..750).all(|k| hold.pose(f64::from(k) / 30.0).pos == at), "a hold moved");
        assert!((0..750).any(|k| at.lerp(at, f64::from(k) / 750.0) != at), "glam's lerp held still too");
        for (text, wants) in [
            ("{}", "non-empty JSON array"),
            ("[]", "non-empty JSON array"),
            ("nope", "not JSON"),
            (r#"[{"pos": [0,0,1], "look_at": [0,0,0]}]"#, "missing \"t\""),
            (r#"[{"t": 0, "pos": [0,0], "look_at": [0,0,0]}]"#, "\"pos\" must be"),
            (r#"[{"t": 0, "pos": [0,0,1]}]"#, "missing \"look_at\""),
            (
                r#"[{"t": 1, "pos": [0,0,1], "look_at": [0,0,0]}, {"t": 1, "pos": [0,0,2], "look_at": [0,0,0]}]"#,
                "not after",
            ),
        ] {
            let error = Flight::from_json(text).expect_err(text).to_string();
            assert!(error.contains(wants), "{text}: {error}");
        }
    }
}
