//! The Aravis colour source against Aravis's own fake GigE Vision camera on 127.0.0.1: the
//! in-process one (frames drawn by the test) and the `arv-fake-gv-camera-0.8` program (losing
//! packets). Nothing here broadcasts: every Aravis discovery interface is disabled and cameras
//! are opened by address.
//!
//! Aravis 0.8's fake camera listens on the fixed GVCP port, so the tests take turns.

use mousepose::core::frame::{ColorFrame, PixelFormat};
use mousepose::io::session::codec::FrameFormat;
use mousepose::io::session::meta::CameraRole;
use mousepose::runtime::capture::aravis::{AravisColor, AravisConfig, Trigger, list_devices};
use mousepose::runtime::capture::{CaptureError, Clock, FrameSource};
use std::net::UdpSocket;
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use aravis_ext::{FakeCamera, FakeCameraConfig, GVCP_PORT, use_only_interfaces};

static FAKE_PORT: Mutex<()> = Mutex::new(());

/// One test at a time on the fake camera's port, with Aravis's discovery switched off.
pub(crate) fn take_port() -> MutexGuard<'static, ()> {
    let guard = FAKE_PORT.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    use_only_interfaces(&[]);
    guard
}

/// The test pattern: each frame a ramp shifted by its frame id.
fn pattern(frame_id: u64, x: usize, y: usize) -> u8 {
    ((frame_id as usize * 7 + x + 3 * y) % 251) as u8
}

pub(crate) fn start_fake(config: &FakeCameraConfig) -> FakeCamera {
    let fill = Box::new(|frame: &mut [u8], width: u32, height: u32, frame_id: u64| {
        let width = width as usize;
        let bpp = frame.len() / (width * height as usize).max(1);
        for (i, byte) in frame.iter_mut().enumerate() {
            let pixel = i / bpp.max(1);
            *byte = pattern(frame_id, pixel % width, pixel / width);
        }
    });
    FakeCamera::start(config, fill).expect("fake camera starts on 127.0.0.1")
}

fn config(region: Option<(u32, u32, u32, u32)>) -> AravisConfig {
    AravisConfig {
        address: Some("127.0.0.1".into()),
        pixel_format: PixelFormat::Mono8,
        region,
        fps: Some(100.0),
        buffers: 4,
        ..AravisConfig::default()
    }
}

/// Reads until `n` frames came or `limit` passed.
fn read_frames(source: &mut AravisColor, n: usize, limit: Duration) -> Vec<ColorFrame> {
    let deadline = Instant::now() + limit;
    let mut frames = Vec::new();
    while frames.len() < n && Instant::now() < deadline {
        if let Some(frame) = source
            .next_frame(Duration::from_millis(200))
            .expect("the camera stays reachable")
        {
            frames.push(frame);
        }
    }
    frames
}

fn assert_pattern(frame: &ColorFrame) {
    let width = frame.width as usize;
    assert_eq!(frame.data.len(), width * frame.height as usize);
    for (i, &byte) in frame.data.iter().enumerate() {
        assert_eq!(
            byte,
            pattern(frame.stamp.seq, i % width, i / width),
            "pixel {i} of {:?}",
            frame.stamp
        );
    }
}

#[test]
fn frames_from_the_in_process_fake_camera_keep_their_content_and_order() {
    let _port = take_port();
    let fake = start_fake(&FakeCameraConfig {
        serial: "MP-COLOR-1".into(),
        ..FakeCameraConfig::default()
    });
    let mut source = AravisColor::open(&config(Some((0, 0, 64, 48)))).unwrap();
    let meta = source.meta();
    assert_eq!(meta.role, CameraRole::Color);
    assert_eq!(meta.backend, "aravis");
    assert_eq!(meta.serial, "MP-COLOR-1");
    assert!(!meta.model.is_empty());
    assert_eq!((meta.width, meta.height), (64, 48));
    assert_eq!(meta.pixel_format, FrameFormat::Color(PixelFormat::Mono8));
    assert!((meta.fps - 100.0).abs() < 1.0, "{}", meta.fps);

    let clock = Clock::Monotonic;
    let before_ns = clock.now_ns();
    source.start(&clock).unwrap();
    let frames = read_frames(&mut source, 12, Duration::from_secs(10));
    source.stop().unwrap();
    assert!(frames.len() >= 10, "only {} frames", frames.len());
    for frame in &frames {
        assert_eq!((frame.width, frame.height, frame.format), (64, 48, PixelFormat::Mono8));
        assert_pattern(frame);
        assert!(frame.stamp.host_ns <= clock.now_ns());
        assert!(frame.stamp.host_ns + 1_000_000_000 >= before_ns);
        assert!(frame.stamp.device_ns > 0);
    }
    for pair in frames.windows(2) {
        assert!(pair[0].stamp.seq < pair[1].stamp.seq, "{:?}", pair);
        assert!(pair[0].stamp.host_ns <= pair[1].stamp.host_ns, "{:?}", pair);
    }
    // Distinct frames, not one image repeated.
    assert_ne!(frames[0].data, frames[1].data);

    let devices = list_devices(&["127.0.0.1".into(), "not an address".into()]);
    assert_eq!(devices.len(), 1, "{devices:?}");
    assert_eq!(devices[0].id, "127.0.0.1");
    assert_eq!(devices[0].serial, "MP-COLOR-1");
    drop(fake);
}

#[test]
fn settings_are_applied_or_refused_with_the_camera_range() {
    let _port = take_port();
    // A camera model without RGB8, from Aravis's own description of the fake camera.
    let xml = aravis_ext::default_genicam_xml();
    let start = xml
        .find("<EnumEntry Name=\"RGB8\"")
        .expect("the fake camera offers RGB8");
    let end = start + xml[start..].find("</EnumEntry>").unwrap() + "</EnumEntry>".len();
    let dir = tempfile::tempdir().unwrap();
    let genicam = dir.path().join("no-rgb8.xml");
    let xml = format!("{}{}", &xml[..start], &xml[end..]);
    // ... and without a software trigger.
    let start = xml
        .find("<EnumEntry Name=\"Software\"")
        .expect("the fake camera offers a software trigger");
    let end = start + xml[start..].find("</EnumEntry>").unwrap() + "</EnumEntry>".len();
    std::fs::write(&genicam, format!("{}{}", &xml[..start], &xml[end..])).unwrap();
    let fake = start_fake(&FakeCameraConfig {
        serial: "MP-COLOR-2".into(),
        genicam_file: Some(genicam),
        ..FakeCameraConfig::default()
    });

    // A region is applied, and frames come in that size.
    let mut source = AravisColor::open(&AravisConfig {
        exposure_us: Some(2_000.0),
        gain_db: Some(1.0),
        serial: Some("MP-COLOR-2".into()),
        ..config(Some((16, 8, 32, 24)))
    })
    .unwrap();
    assert_eq!((source.meta().width, source.meta().height), (32, 24));
    source.start(&Clock::Monotonic).unwrap();
    let frames = read_frames(&mut source, 3, Duration::from_secs(10));
    source.stop().unwrap();
    assert_eq!(frames.len(), 3);
    for frame in &frames {
        assert_eq!((frame.width, frame.height), (32, 24));
        assert_pattern(frame);
    }

    let refusal = |config: AravisConfig| match AravisColor::open(&config) {
        Err(error @ CaptureError::Refused { .. }) => error.to_string(),
        other => panic!("expected a refusal, got {other:?}"),
    };
    let message = refusal(AravisConfig {
        pixel_format: PixelFormat::Rgb8,
        ..config(None)
    });
    assert!(message.contains("pixel format rgb8"), "{message}");
    assert!(message.contains("Mono8") && message.contains("BayerRG8"), "{message}");
    assert!(!message.contains("RGB8,") && !message.contains("RGB8]"), "{message}");

    let message = refusal(AravisConfig {
        exposure_us: Some(1e9),
        ..config(None)
    });
    assert!(message.contains("exposure 1000000000 us"), "{message}");
    assert!(message.contains("allows 10 to 10000000 us"), "{message}");

    let message = refusal(config(Some((0, 0, 4096, 16))));
    assert!(
        message.contains("region") && message.contains("width 4096"),
        "{message}"
    );
    assert!(message.contains("2048"), "{message}");

    let message = refusal(AravisConfig {
        trigger: Trigger::Line("Line7".into()),
        ..config(None)
    });
    assert!(message.contains("Line7") && message.contains("Line0"), "{message}");

    let message = refusal(AravisConfig {
        trigger: Trigger::Depth,
        ..config(None)
    });
    assert!(
        message.contains("trigger \"depth\"") && message.contains("software trigger") && message.contains("[Line0]"),
        "{message}"
    );

    let message = refusal(AravisConfig {
        fps: Some(1e6),
        ..config(None)
    });
    assert!(message.contains("frame rate"), "{message}");

    // The serial is checked against the camera at the address.
    match AravisColor::open(&AravisConfig {
        serial: Some("SOMEONE-ELSE".into()),
        ..config(None)
    }) {
        Err(CaptureError::NotFound { id, .. }) => assert!(id.contains("MP-COLOR-2"), "{id}"),
        other => panic!("expected not found, got {other:?}"),
    }
    drop(fake);
}

/// Kills and reaps the fake camera program however the test ends.
pub(crate) struct ChildGuard(pub(crate) Child);

impl Drop for ChildGuard {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn gvcp_port_taken() -> bool {
    UdpSocket::bind(("127.0.0.1", GVCP_PORT)).is_err()
}

/// Starts the `arv-fake-gv-camera-0.8` program on 127.0.0.1 with `args` and waits until it
/// listens. Take the port first ([`take_port`]).
pub(crate) fn start_fake_program(args: &[&str]) -> ChildGuard {
    let mut child = ChildGuard(
        Command::new("arv-fake-gv-camera-0.8")
            .args(["-i", "127.0.0.1"])
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("arv-fake-gv-camera-0.8 runs (package aravis-tools)"),
    );
    let deadline = Instant::now() + Duration::from_secs(10);
    while !gvcp_port_taken() {
        let exited = child.0.try_wait().expect("the fake camera program can be waited for");
        assert!(exited.is_none(), "the fake camera program exited");
        assert!(Instant::now() < deadline, "the fake camera program never listened");
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

#[test]
fn a_lossy_camera_program_gives_only_whole_frames_and_counts_the_rest() {
    let _port = take_port();
    let child = start_fake_program(&["-s", "MP-LOSSY", "-r", "200"]);

    let mut source = AravisColor::open(&config(Some((0, 0, 256, 64)))).unwrap();
    assert_eq!(source.meta().serial, "MP-LOSSY");
    source.start(&Clock::Monotonic).unwrap();
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut frames = Vec::new();
    while Instant::now() < deadline {
        if let Some(frame) = source.next_frame(Duration::from_millis(200)).unwrap() {
            frames.push(frame);
        }
        let lost: u64 = source.losses().iter().map(|(_, n)| n).sum();
        if frames.len() >= 5 && lost >= 3 {
            break;
        }
    }
    let losses = source.losses();
    source.stop().unwrap();
    drop(child);

    assert!(
        frames.len() >= 5,
        "only {} whole frames; losses {losses:?}",
        frames.len()
    );
    let lost: u64 = losses.iter().map(|(_, n)| n).sum();
    assert!(lost >= 3, "losses {losses:?}");
    assert!(
        losses
            .iter()
            .all(|(reason, _)| ["incomplete", "timeout"].contains(reason)),
        "{losses:?}"
    );
    // Aravis's own test pattern: a diagonal ramp shifted by the frame id. Every frame passed
    // on is whole.
    for frame in &frames {
        assert_eq!((frame.width, frame.height), (256, 64));
        for (i, &byte) in frame.data.iter().enumerate() {
            let (x, y) = (i % 256, i / 256);
            assert_eq!(
                u64::from(byte),
                (x as u64 + y as u64 + frame.stamp.seq) % 255,
                "pixel {i} of {:?}",
                frame.stamp
            );
        }
    }
    for pair in frames.windows(2) {
        assert!(pair[0].stamp.seq < pair[1].stamp.seq);
    }
}

#[test]
fn a_missing_camera_is_a_clear_error_not_a_hang() {
    let _port = take_port();
    assert!(!gvcp_port_taken(), "something listens on the GVCP port");
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::Builder::new()
        .name("open-missing".into())
        .spawn(move || {
            let nothing = AravisColor::open(&config(None)).map(|_| ());
            let no_address = AravisColor::open(&AravisConfig {
                address: Some("camera.local".into()),
                ..config(None)
            })
            .map(|_| ());
            let nothing_named = AravisColor::open(&AravisConfig {
                address: None,
                ..config(None)
            })
            .map(|_| ());
            let _ = tx.send((nothing, no_address, nothing_named));
        })
        .unwrap();
    let (nothing, no_address, nothing_named) = rx
        .recv_timeout(Duration::from_secs(60))
        .expect("opening a missing camera hangs");

    let error = nothing.unwrap_err();
    let message = format!("{error}");
    assert!(matches!(error, CaptureError::Driver { .. }), "{error:?}");
    assert!(
        message.contains("no GigE Vision camera answers at 127.0.0.1"),
        "{message}"
    );
    assert!(std::error::Error::source(&error).is_some());

    let message = no_address.unwrap_err().to_string();
    assert!(message.contains("not an IPv4 address"), "{message}");
    let message = nothing_named.unwrap_err().to_string();
    assert!(message.contains("neither an address nor a serial"), "{message}");
}

/// Issue 46: a colour camera triggered in step with the depth camera (`trigger = "depth"`)
/// makes one frame per depth frame, delivered just before it, however its own frame rate is
/// set; without depth frames it is triggered at its own rate.
#[test]
fn issue46_a_camera_triggered_by_the_depth_beat_delivers_each_frame_just_before_the_depth_frame() {
    use mousepose::runtime::capture::beat::DepthBeat;
    use std::sync::Arc;
    let _port = take_port();
    let fake = start_fake(&FakeCameraConfig {
        serial: "MP-COLOR-STEP".into(),
        trigger_frequency: Some(2_000.0),
        ..FakeCameraConfig::default()
    });
    let mut source = AravisColor::open(&AravisConfig {
        trigger: Trigger::Depth,
        fps: Some(10.0),
        ..config(Some((0, 0, 64, 48)))
    })
    .unwrap();
    let beat = Arc::new(DepthBeat::default());
    source.in_step_with(&beat);
    let clock = Clock::Monotonic;
    source.start(&clock).unwrap();

    // Without depth frames: its own 10 frames/s.
    let own = read_frames(&mut source, 100, Duration::from_millis(1_000));
    assert!(
        (6..=14).contains(&own.len()),
        "{} frames in 1 s at its own 10 fps",
        own.len()
    );

    // A depth camera at 25 frames/s, its frames arriving on a thread of their own.
    let period_ns = 40_000_000;
    let beats = {
        let beat = Arc::clone(&beat);
        std::thread::Builder::new()
            .name("depth-beat".into())
            .spawn(move || {
                let start = Clock::Monotonic.now_ns();
                let mut arrivals = Vec::new();
                for k in 0..50u64 {
                    let due = start + k * period_ns;
                    let now = Clock::Monotonic.now_ns();
                    std::thread::sleep(Duration::from_nanos(due.saturating_sub(now)));
                    let arrived = Clock::Monotonic.now_ns();
                    beat.beat(arrived);
                    arrivals.push(arrived);
                }
                arrivals
            })
            .unwrap()
    };
    let frames = read_frames(&mut source, 1_000, Duration::from_millis(2_100));
    let arrivals = beats.join().unwrap();
    source.stop().unwrap();
    assert_eq!(source.losses(), vec![], "no trigger refused");
    // After the first few depth frames (the period is learnt), one colour frame a depth frame.
    let settled: Vec<i64> = frames
        .iter()
        .filter(|f| f.stamp.host_ns > arrivals[5] && f.stamp.host_ns < arrivals[49] + period_ns / 2)
        .map(|f| {
            let host = f.stamp.host_ns as i64;
            arrivals
                .iter()
                .map(|&a| host - a as i64)
                .min_by_key(|d| d.abs())
                .unwrap()
        })
        .collect();
    let mut sorted = settled.clone();
    sorted.sort_unstable();
    assert!(
        (34..=46).contains(&settled.len()),
        "{} colour frames for 44 depth frames: {settled:?}",
        settled.len()
    );
    // Before the depth frame at the median, and within the pairing's tolerance (half the
    // depth camera's period) nearly always, whatever the host's load does to the delivery.
    let median = sorted[sorted.len() / 2];
    assert!(
        (-15_000_000..=1_000_000).contains(&median),
        "colour frames at {median} ns from their depth frames at the median: {settled:?}"
    );
    let within = settled.iter().filter(|d| d.abs() < period_ns as i64 / 2).count();
    assert!(within * 10 >= settled.len() * 9, "{settled:?}");
    drop(fake);
}
