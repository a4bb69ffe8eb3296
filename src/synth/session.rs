//! Synthetic sessions: a continuous behaviour sequence rendered as a recorded session, exactly
//! as `record` writes one: full depth and colour frames with each camera's own clock (offset
//! and drifting from the other), host arrival times with jitter, an occasional dropped frame
//! in the event log, and the ground truth (24 joints per depth frame and the true pairing).

use super::animate::{Animator, Group};
use super::body::skin;
use super::mouse::{MouseInstance, fit_in_cage, pose_mouse};
use super::render::Cage;
use super::views::{render_bottom_frame, render_top_frame};
use super::{Carriage, ENGINE_VERSION, Mice, item_rng, random_placement, varied_build};
use crate::core::frame::{ColorFrame, DepthFrame, PixelFormat, Stamp};
use crate::core::geometry::Rig;
use crate::core::image::Region;
use crate::core::noise::DepthNoise;
use crate::io::session::{
    BackendName, CameraMeta, CameraRole, FrameFormat, SessionError, SessionEvent, SessionMeta, SessionSource,
    SessionSummary, SessionWriter,
};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;
use std::path::Path;
use std::path::PathBuf;

/// The `created` time written into synthetic sessions: fixed, so a seed gives byte-identical
/// output.
pub const SYNTHETIC_CREATED: &str = "2000-01-01T00:00:00Z";

/// What to generate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SessionSpec {
    pub seconds: f64,
    pub fps: f64,
    pub seed: u64,
    pub noise: DepthNoise,
    /// Colour camera binning (1 = the full 1280x1024 sensor).
    pub color_binning: u32,
    pub color_format: PixelFormat,
    /// Whether the session has a colour camera at all (depth-only rigs have none).
    pub color: bool,
    /// The standard mice, mice well outside the training range, or either by the seed.
    pub mice: Mice,
    /// A mouse of exactly this build instead ([`super::Build::exact`]).
    pub build: Option<super::Build>,
    /// What the mouse does (anything, stay in place, walk).
    pub activity: super::animate::Activity,
    /// How the depth camera shows the tail (the truth keeps the tail's joints).
    pub tail: TailLook,
    /// How many mice share the cage (1 to [`MOST_MICE`]): the first is the mouse of the seed,
    /// the others each of a build of its own ([`super::varied_build`]), animated together
    /// ([`Group`]).
    pub count: usize,
}

/// The most mice a synthetic session renders in its cage: as many as are followed.
pub use crate::vision::identity::MOST_MICE;

/// How a depth camera shows a mouse's tail: real ones show it in each of these ways.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TailLook {
    /// As it is: 3-5 mm thick on the floor, 2-4 mm high (often lost in the noise).
    #[default]
    Visible,
    /// Not at all, as a depth camera that does not see a 3-5 mm tail shows it.
    Hidden,
    /// Blurred and raised by mixed pixels: about 6 mm wide, its top reading
    /// [`RAISED_TAIL_TOP_MM`] above the floor at its base falling to 10 mm at its tip (a real
    /// Kinect's tail reads 10-30 mm while the back reads 30-40 mm).
    Raised,
}

/// The raised tail's top at its base (mm above the floor); see [`TailLook::Raised`].
pub const RAISED_TAIL_TOP_MM: f64 = 24.0;
/// The raised tail's top at its tip (mm).
const RAISED_TAIL_TIP_MM: f64 = 10.0;
/// The raised tail's radius, at least (mm).
const RAISED_TAIL_RADIUS_MM: f64 = 3.0;

impl Default for SessionSpec {
    fn default() -> Self {
        Self {
            seconds: 10.0,
            fps: 30.0,
            seed: 0,
            noise: DepthNoise {
                model: crate::core::noise::NoiseModel::StructuredLight,
                gaussian_mm: 0.0,
            },
            color_binning: 1,
            color_format: PixelFormat::BayerRg8,
            color: true,
            mice: Mice::Standard,
            build: None,
            activity: super::animate::Activity::Mixed,
            tail: TailLook::Visible,
            count: 1,
        }
    }
}

/// The mice of a session, animated together, with their carriages: the first is the mouse of
/// the seed ([`session_mouse`]), each other one of a varied build drawn from streams of its own.
fn session_group(spec: &SessionSpec) -> (Group, Vec<Carriage>) {
    let (first, carriage) = session_mouse(spec.seed, spec.mice, spec.build);
    let mut mice = vec![first.with_activity(spec.activity)];
    let mut carriages = vec![carriage];
    for k in 1..spec.count.clamp(1, MOST_MICE) as u64 {
        let (build, carriage) = varied_build(&mut item_rng(spec.seed, STREAM_VARIETY, k));
        mice.push(Animator::new(item_rng(spec.seed, STREAM_MOUSE, k), build).with_activity(spec.activity));
        carriages.push(carriage);
    }
    (Group::new(mice, item_rng(spec.seed, STREAM_GROUP, 0)), carriages)
}

/// The animated mouse of the session of a seed, at its start: what [`write_session`] renders
/// (tests read its behaviour, e.g. its walking, without rendering).
pub fn session_animator(seed: u64) -> Animator {
    session_mouse(seed, Mice::Standard, None).0
}

/// The animated mouse of a seed and its carriage: the standard mice's build comes from the
/// mouse's own random stream (as it always did), a varied mouse's from a stream of its own.
pub(crate) fn session_mouse(seed: u64, mice: Mice, exact: Option<super::Build>) -> (Animator, Carriage) {
    let mut mouse_rng = item_rng(seed, STREAM_MOUSE, 0);
    if let Some(exact) = exact {
        let build = exact.exact(&mut mouse_rng);
        return (Animator::new(mouse_rng, build), Carriage::default());
    }
    let build = random_placement(&mut mouse_rng);
    match mice.of_item(seed) {
        Mice::Standard | Mice::Mixed => (Animator::new(mouse_rng, build), Carriage::default()),
        Mice::Varied => {
            let (build, carriage) = varied_build(&mut item_rng(seed, STREAM_VARIETY, 0));
            (Animator::new(mouse_rng, build), carriage)
        }
    }
}

// RNG streams of a session.
const STREAM_MOUSE: u64 = 10;
const STREAM_CLOCKS: u64 = 11;
const STREAM_DEPTH: u64 = 12;
const STREAM_COLOR: u64 = 13;
const STREAM_VARIETY: u64 = 14;
const STREAM_GROUP: u64 = 15;

/// The simulated cameras' minimal transport latencies (ms), recorded in the session's
/// metadata as the colour camera's latency relative to the depth camera's.
const DEPTH_LATENCY_MS: f64 = 6.0;
const COLOR_LATENCY_MS: f64 = 3.0;

/// One camera's device clock and transport to the host.
#[derive(Clone, Copy, Debug)]
struct CameraClock {
    offset_ns: f64,
    drift_ppm: f64,
    jitter_ns: f64,
    latency_ns: f64,
    latency_jitter_ns: f64,
}

impl CameraClock {
    fn random(rng: &mut impl Rng, latency_ms: f64) -> Self {
        Self {
            offset_ns: rng.gen_range(1e9..1e12),
            drift_ppm: rng.gen_range(-40.0..40.0),
            jitter_ns: 20_000.0,
            latency_ns: latency_ms * 1e6,
            latency_jitter_ns: latency_ms * 0.25e6,
        }
    }

    fn device_ns(&self, t_s: f64, rng: &mut impl Rng) -> u64 {
        let n: f64 = Normal::new(0.0, self.jitter_ns).map_or(0.0, |d| d.sample(rng));
        (self.offset_ns + t_s * 1e9 * (1.0 + self.drift_ppm * 1e-6) + n).max(0.0) as u64
    }

    fn host_ns(&self, host0_ns: f64, t_s: f64, rng: &mut impl Rng) -> u64 {
        let n: f64 = Normal::new(0.0, self.latency_jitter_ns).map_or(0.0, |d| d.sample(rng));
        (host0_ns + t_s * 1e9 + self.latency_ns + n.abs()) as u64
    }
}

/// A frame to render: which camera, its stamp, the true time and the posed mice.
struct Shot {
    role: CameraRole,
    stamp: Stamp,
    time_s: f64,
    dropped: bool,
    mice: Vec<MouseInstance>,
}

/// The camera metadata of a synthetic session.
fn cameras(rig: &Rig, spec: &SessionSpec) -> Vec<CameraMeta> {
    let mut out = vec![CameraMeta {
        role: CameraRole::Depth,
        backend: BackendName::SYNTHETIC,
        model: "synthetic structured-light depth camera".to_owned(),
        serial: format!("SYN-D-{}", spec.seed),
        firmware: format!("engine {ENGINE_VERSION}"),
        width: rig.depth.intrinsics.width,
        height: rig.depth.intrinsics.height,
        pixel_format: FrameFormat::Depth16,
        fps: spec.fps,
    }];
    if spec.color {
        out.push(CameraMeta {
            role: CameraRole::Color,
            backend: BackendName::SYNTHETIC,
            model: "synthetic GigE colour camera".to_owned(),
            serial: format!("SYN-C-{}", spec.seed),
            firmware: format!("engine {ENGINE_VERSION}"),
            width: rig.color.intrinsics.width,
            height: rig.color.intrinsics.height,
            pixel_format: FrameFormat::Color(spec.color_format),
            fps: spec.fps,
        });
    }
    out
}

/// Plans every frame: times, stamps, drops and the animated mouse at each instant.
fn plan(spec: &SessionSpec) -> (Vec<Shot>, Vec<SessionEvent>, u64) {
    let mut clocks_rng = item_rng(spec.seed, STREAM_CLOCKS, 0);
    let depth_clock = CameraClock::random(&mut clocks_rng, DEPTH_LATENCY_MS);
    let color_clock = CameraClock::random(&mut clocks_rng, COLOR_LATENCY_MS);
    let host0_ns = 5e9;
    let period = 1.0 / spec.fps;
    let depth_count = (spec.seconds * spec.fps).round() as u64;
    // The colour camera free-runs a fraction of a frame after the depth camera, with its own
    // crystal (its period differs by the two clocks' drift).
    let color_phase = clocks_rng.gen_range(0.15..0.35) * period;
    let color_period = period * (1.0 + (depth_clock.drift_ppm - color_clock.drift_ppm) * 1e-6);
    let color_count = if spec.color {
        ((spec.seconds - color_phase) / color_period).floor().max(0.0) as u64 + 1
    } else {
        0
    };
    // One guaranteed drop per camera in longer sessions, and a rare random one.
    let forced = |rng: &mut rand_chacha::ChaCha8Rng, n: u64| (n >= 20).then(|| rng.gen_range(n / 4..3 * n / 4));
    let forced_depth = forced(&mut clocks_rng, depth_count);
    let forced_color = forced(&mut clocks_rng, color_count);

    let mut times: Vec<(f64, CameraRole, u64)> = (0..depth_count)
        .map(|k| (k as f64 * period, CameraRole::Depth, k))
        .chain((0..color_count).map(|k| (color_phase + k as f64 * color_period, CameraRole::Color, k)))
        .collect();
    times.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));

    let (mut group, carriages) = session_group(spec);
    let mut now = 0.0;
    let mut shots = Vec::with_capacity(times.len());
    let mut events = Vec::new();
    let mut last_host = [0u64; 2];
    for (t, role, seq) in times {
        group.advance(t - now);
        now = t;
        let mice = group
            .mice()
            .iter()
            .zip(&carriages)
            .map(|(animator, carriage)| {
                let (mut params, placement) = animator.state();
                carriage.apply(&mut params);
                let mut mouse = pose_mouse(&params, &placement);
                fit_in_cage(&mut mouse, 3.0);
                mouse
            })
            .collect();
        let (clock, forced) = match role {
            CameraRole::Depth => (&depth_clock, forced_depth),
            CameraRole::Color => (&color_clock, forced_color),
        };
        let device_ns = clock.device_ns(t, &mut clocks_rng);
        let slot = usize::from(role == CameraRole::Color);
        let host_ns = clock.host_ns(host0_ns, t, &mut clocks_rng).max(last_host[slot] + 1);
        last_host[slot] = host_ns;
        let dropped = forced == Some(seq) || clocks_rng.gen_bool(0.002);
        if dropped {
            events.push(SessionEvent::FramesDropped {
                host_ns,
                role,
                seq_from: seq,
                count: 1,
                reason: "camera dropped the frame".to_owned(),
            });
        }
        shots.push(Shot {
            role,
            stamp: Stamp {
                seq,
                device_ns,
                host_ns,
            },
            time_s: t,
            dropped,
            mice,
        });
    }
    let end_host = last_host.into_iter().max().unwrap_or(host0_ns as u64) + 1;
    (shots, events, end_host)
}

/// Renders a full depth frame: the cage, the mouse, the sensor's noise.
fn depth_frame(
    rig: &Rig,
    background: &[f32],
    shot: &Shot,
    noise: &DepthNoise,
    seed: u64,
    tail: TailLook,
) -> DepthFrame {
    let i = &rig.depth.intrinsics;
    let mut rng = item_rng(seed, STREAM_DEPTH, shot.stamp.seq);
    DepthFrame {
        stamp: shot.stamp,
        width: i.width,
        height: i.height,
        data: render_top_frame(&rig.depth, background, &skins(&shot.mice, tail), noise, &mut rng),
    }
}

fn color_frame(rig: &Rig, shot: &Shot, format: PixelFormat, seed: u64, tail: TailLook) -> ColorFrame {
    let i = &rig.color.intrinsics;
    let mut rng = item_rng(seed, STREAM_COLOR, shot.stamp.seq);
    let (data, _) = render_bottom_frame(
        &rig.color,
        &shot.mice[0],
        // Seen from below, a raised tail is the tail as it is.
        &skins(
            &shot.mice,
            if tail == TailLook::Raised {
                TailLook::Visible
            } else {
                tail
            },
        ),
        format,
        &mut rng,
    );
    ColorFrame {
        stamp: shot.stamp,
        width: i.width,
        height: i.height,
        format,
        data,
    }
}

/// A rendered frame ready to write.
enum Rendered {
    Depth(DepthFrame),
    Color(ColorFrame),
}

/// Errors generating a synthetic session.
#[derive(Debug, thiserror::Error)]
pub enum SynthSessionError {
    #[error(transparent)]
    Session(#[from] SessionError),
    #[error("cannot write the preview {path:?}")]
    Preview {
        path: PathBuf,
        #[source]
        source: crate::core::image::ImageError,
    },
}

/// The session's description: the synthetic rig's cameras, the colour camera's latency, and
/// what made it (seed, length, noise, activity, tail) under `[synthetic]`.
fn session_meta(rig: &Rig, spec: &SessionSpec) -> SessionMeta {
    let mut meta = SessionMeta::new(SYNTHETIC_CREATED, SessionSource::Synthetic, cameras(rig, spec));
    meta.rig = Some(*rig);
    if spec.color {
        meta.color_latency_ns = Some(((COLOR_LATENCY_MS - DEPTH_LATENCY_MS) * 1e6) as i64);
    }
    meta.notes = "synthetic session: the created time is fixed so that a seed gives identical files".to_owned();
    let mut table = toml::Table::new();
    table.insert("seed".into(), toml::Value::Integer(spec.seed as i64));
    table.insert("seconds".into(), toml::Value::Float(spec.seconds));
    table.insert("fps".into(), toml::Value::Float(spec.fps));
    table.insert(
        "noise_model".into(),
        toml::Value::String(spec.noise.model.name().to_owned()),
    );
    table.insert("noise_mm".into(), toml::Value::Float(spec.noise.gaussian_mm));
    table.insert(
        "color_binning".into(),
        toml::Value::Integer(i64::from(spec.color_binning)),
    );
    table.insert("engine_version".into(), toml::Value::Integer(i64::from(ENGINE_VERSION)));
    // How many mice: only with more than one, so one mouse's sessions stay as they were.
    if spec.count > 1 {
        table.insert("mice".into(), toml::Value::Integer(spec.count as i64));
    }
    // Only when not the default, so the default sessions' files stay as they were.
    if spec.activity != super::animate::Activity::Mixed {
        let name = format!("{:?}", spec.activity).to_lowercase();
        table.insert("activity".into(), toml::Value::String(name));
    }
    match spec.tail {
        TailLook::Visible => {}
        TailLook::Hidden => {
            table.insert("tail_hidden".into(), toml::Value::Boolean(true));
        }
        TailLook::Raised => {
            table.insert("tail".into(), toml::Value::String("raised".into()));
        }
    }
    meta.synthetic = Some(table);
    meta
}

/// Generates a session into `dir` (which must exist and be empty), calling `progress` with
/// the number of frames done out of the total.
///
/// # Errors
/// When the session cannot be written.
pub fn write_session(
    dir: &Path,
    spec: &SessionSpec,
    mut progress: impl FnMut(u64, u64),
) -> Result<SessionSummary, SynthSessionError> {
    let rig = Rig::default_rig().with_color_binning(spec.color_binning);
    let meta = session_meta(&rig, spec);

    let (shots, drop_events, end_host) = plan(spec);
    let mut writer = SessionWriter::create(dir, &meta)?;
    let start_host = shots.first().map_or(0, |s| s.stamp.host_ns.saturating_sub(1_000_000));
    writer.log_event(&SessionEvent::SessionStarted { host_ns: start_host })?;
    for c in &meta.cameras {
        writer.log_event(&SessionEvent::CameraOpened {
            host_ns: start_host,
            role: c.role,
            model: c.model.clone(),
            serial: c.serial.clone(),
        })?;
    }
    let colors: Vec<(f64, u64)> = shots
        .iter()
        .filter(|s| s.role == CameraRole::Color && !s.dropped)
        .map(|s| (s.time_s, s.stamp.seq))
        .collect();
    let background = Cage::new(&rig.depth).depth(Region::full(&rig.depth.intrinsics));
    let total = shots.len() as u64;
    let mut drops = drop_events.into_iter().peekable();
    const CHUNK: usize = 32;
    for (c, chunk) in shots.chunks(CHUNK).enumerate() {
        let rendered: Vec<Option<Rendered>> = chunk
            .par_iter()
            .map(|shot| {
                (!shot.dropped).then(|| match shot.role {
                    CameraRole::Depth => {
                        Rendered::Depth(depth_frame(&rig, &background, shot, &spec.noise, spec.seed, spec.tail))
                    }
                    CameraRole::Color => {
                        Rendered::Color(color_frame(&rig, shot, spec.color_format, spec.seed, spec.tail))
                    }
                })
            })
            .collect();
        for (shot, frame) in chunk.iter().zip(rendered) {
            while let Some(e) = drops.next_if(|e| e.host_ns().is_some_and(|h| h <= shot.stamp.host_ns)) {
                writer.log_event(&e)?;
            }
            match frame {
                Some(Rendered::Depth(f)) => {
                    writer.write_depth(&f)?;
                    let time_ns = (shot.time_s * 1e9).round() as u64;
                    if let [one] = shot.mice.as_slice() {
                        writer.write_truth(shot.stamp.seq, time_ns, &one.joints)?;
                    } else {
                        for (k, mouse) in shot.mice.iter().enumerate() {
                            writer.write_truth_of(shot.stamp.seq, time_ns, k + 1, &mouse.joints)?;
                        }
                    }
                    writer.write_truth_pair(shot.stamp.seq, true_partner(&colors, shot.time_s, spec.fps))?;
                }
                Some(Rendered::Color(f)) => writer.write_color(&f)?,
                None => {}
            }
        }
        progress(((c + 1) * CHUNK).min(shots.len()) as u64, total);
    }
    for e in drops {
        writer.log_event(&e)?;
    }
    let summary = writer.finish_at(end_host)?;
    // A picture of the instant half-way through.
    if let Some(mid) = shots
        .iter()
        .filter(|s| s.role == CameraRole::Depth)
        .nth((spec.seconds * spec.fps / 2.0) as usize)
    {
        let mut rng = item_rng(spec.seed, STREAM_DEPTH, u64::MAX);
        let path = dir.join(PREVIEW_FILE);
        super::preview::preview(&rig, &mid.mice[0], &spec.noise, &mut rng)
            .write_png(&path)
            .map_err(|source| SynthSessionError::Preview { path, source })?;
    }
    Ok(summary)
}

/// The picture of one instant that synthetic sessions carry.
pub const PREVIEW_FILE: &str = "preview.png";

/// The colour frame taken closest in true time to a depth frame, if one was delivered within
/// half a frame interval. `colors` holds `(true time, seq)` of delivered colour frames in time
/// order.
fn true_partner(colors: &[(f64, u64)], depth_time_s: f64, fps: f64) -> Option<u64> {
    let k = colors.partition_point(|(t, _)| *t < depth_time_s);
    [k.checked_sub(1), Some(k)]
        .into_iter()
        .flatten()
        .filter_map(|i| colors.get(i))
        .map(|&(t, seq)| ((t - depth_time_s).abs(), seq))
        .filter(|(dt, _)| *dt < 0.5 / fps)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, seq)| seq)
}

/// The skins of several mice together, each seen as [`seen_skin`] says.
fn skins(mice: &[MouseInstance], tail: TailLook) -> Vec<super::body::Primitive> {
    mice.iter().flat_map(|m| seen_skin(m, tail)).collect()
}

/// The skin the cameras see, its tail as `tail` says.
pub fn seen_skin(mouse: &MouseInstance, tail: TailLook) -> Vec<super::body::Primitive> {
    use super::body::{Labeller, Shape};
    let is_tail = |p: &super::body::Primitive| p.labeller == Labeller::Fixed(crate::core::skeleton::Part::Tail);
    let mut skin = skin(mouse);
    match tail {
        TailLook::Visible => {}
        TailLook::Hidden => skin.retain(|p| !is_tail(p)),
        TailLook::Raised => {
            let pieces = skin.iter().filter(|p| is_tail(p)).count().max(2);
            for (k, p) in skin.iter_mut().filter(|p| is_tail(p)).enumerate() {
                let Shape::Capsule { a, b, radius } = &mut p.shape else {
                    continue;
                };
                let t = k as f64 / (pieces - 1) as f64;
                *radius = radius.max(RAISED_TAIL_RADIUS_MM);
                let top = RAISED_TAIL_TOP_MM + (RAISED_TAIL_TIP_MM - RAISED_TAIL_TOP_MM) * t;
                let lift = (top - (a.z.max(b.z) + *radius)).max(0.0);
                a.z += lift;
                b.z += lift;
            }
        }
    }
    skin
}
