//! The OpenNI2 depth source against Debian's Dummy device (320x240 depth at 30 fps) and `.oni`
//! recordings made from it: streaming, mode refusal, unknown devices, recording and playing
//! back, and the device list.
//!
//! OpenNI2 is one context per process, so these tests run one at a time (`serial()`).

use mousepose::core::frame::DepthFrame;
use mousepose::io::session::{CameraRole, FrameFormat};
use mousepose::runtime::capture::openni::list_devices;
use mousepose::runtime::capture::{CaptureError, Clock, FrameSource, OpenNiConfig, OpenNiDepth};
use openni2 as ni;
use std::path::Path;
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::Duration;

static OPENNI: Mutex<()> = Mutex::new(());

/// Holds OpenNI2 for one test.
pub(crate) fn serial() -> MutexGuard<'static, ()> {
    OPENNI.lock().unwrap_or_else(PoisonError::into_inner)
}

fn dummy(width: u32, height: u32, fps: u32) -> OpenNiConfig {
    OpenNiConfig {
        uri: Some("Dummy".to_owned()),
        serial: None,
        width,
        height,
        fps,
    }
}

/// Reads `count` frames, failing after a generous number of empty waits.
fn read_frames(source: &mut OpenNiDepth, count: usize, clock: &Clock) -> Vec<DepthFrame> {
    let mut frames = Vec::new();
    for attempt in 0..(count * 10) {
        clock.advance_to(1_000 + attempt as u64);
        if let Some(frame) = source.next_frame(Duration::from_millis(500)).expect("reading Dummy") {
            frames.push(frame);
            if frames.len() == count {
                return frames;
            }
        }
    }
    panic!("only {} of {count} frames arrived", frames.len());
}

#[test]
fn dummy_streams_frames_in_order() {
    let _guard = serial();
    let clock = Clock::replay(1_000);
    let mut source = OpenNiDepth::new(dummy(320, 240, 30));
    source.start(&clock).unwrap();

    let meta = source.meta();
    assert_eq!(meta.role, CameraRole::Depth);
    assert_eq!(meta.backend, "openni2");
    assert_eq!(meta.model, "Table Tennis", "Dummy has no name; its vendor stands in");
    assert_eq!((meta.width, meta.height, meta.fps), (320, 240, 30.0));
    assert_eq!(meta.pixel_format, FrameFormat::Depth16);
    assert_eq!(meta.serial, "", "Dummy reports no serial");

    let frames = read_frames(&mut source, 12, &clock);
    for pair in frames.windows(2) {
        assert!(
            pair[1].stamp.seq > pair[0].stamp.seq,
            "{:?}",
            (pair[0].stamp, pair[1].stamp)
        );
        assert!(pair[1].stamp.device_ns > pair[0].stamp.device_ns);
        assert!(pair[1].stamp.host_ns >= pair[0].stamp.host_ns);
    }
    for frame in &frames {
        assert_eq!((frame.width, frame.height), (320, 240));
        assert_eq!(frame.data.len(), 320 * 240);
        // Dummy stamps frame n at n * 33 ms (device microseconds, here in nanoseconds).
        assert_eq!(frame.stamp.device_ns, frame.stamp.seq * 33_000_000);
        // host_ns is the source's clock when the frame was read.
        assert!((1_000..1_200).contains(&frame.stamp.host_ns));
        // Dummy's top row reads 2000 mm.
        assert!(frame.data[..320].iter().all(|&z| z == 2000));
    }
    assert!(!source.finished(), "a camera never ends");
    assert_eq!(source.recording_frames(), None);
    assert!(source.losses().iter().all(|&(_, n)| n == 0), "{:?}", source.losses());
    source.stop().unwrap();
    source.stop().unwrap();
}

#[test]
fn dummy_runs_on_a_monotonic_clock_and_restarts() {
    let _guard = serial();
    let mut source = OpenNiDepth::new(dummy(0, 0, 0));
    for _ in 0..2 {
        source.start(&Clock::Monotonic).unwrap();
        let frame = (0..20)
            .find_map(|_| source.next_frame(Duration::from_millis(500)).unwrap())
            .expect("a frame within 10 s");
        assert!(frame.stamp.host_ns > 0);
        assert_eq!(
            (source.meta().width, source.meta().height),
            (320, 240),
            "0 takes any mode"
        );
        source.stop().unwrap();
    }
}

#[test]
fn a_mode_the_camera_lacks_is_refused_with_the_modes_it_has() {
    let _guard = serial();
    let mut source = OpenNiDepth::new(dummy(640, 480, 30));
    let error = source.start(&Clock::Monotonic).unwrap_err();
    let CaptureError::Refused { what, reason, .. } = &error else {
        panic!("expected a refusal, got {error:?}");
    };
    assert!(what.contains("640x480@30"), "{what}");
    assert!(reason.contains("320x240@30 depth_1_mm"), "{reason}");
    let message = error.to_string();
    assert!(
        message.contains("Dummy") && message.contains("available modes"),
        "{message}"
    );
    source.stop().unwrap();
}

#[test]
fn unknown_devices_and_files_are_errors_not_panics() {
    let _guard = serial();
    let mut source = OpenNiDepth::new(dummy(320, 240, 30));
    assert!(
        source.next_frame(Duration::from_millis(1)).is_err(),
        "no frame before start"
    );

    for uri in ["no-such-device://0", "/nonexistent/recording.oni"] {
        let config = OpenNiConfig {
            uri: Some(uri.to_owned()),
            ..dummy(320, 240, 30)
        };
        let error = OpenNiDepth::new(config).start(&Clock::Monotonic).unwrap_err();
        assert!(
            matches!(error, CaptureError::NotFound { .. } | CaptureError::Driver { .. }),
            "{uri}: {error:?}"
        );
        assert!(error.to_string().contains(uri), "{error}");
    }

    let config = OpenNiConfig {
        uri: None,
        serial: Some("NO-SUCH-SERIAL".to_owned()),
        ..dummy(320, 240, 30)
    };
    let error = OpenNiDepth::new(config).start(&Clock::Monotonic).unwrap_err();
    assert!(matches!(error, CaptureError::NotFound { .. }), "{error:?}");

    // A file that is not a recording: the driver's own explanation is kept as the cause.
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.oni");
    std::fs::write(&junk, b"not a recording").unwrap();
    let config = OpenNiConfig {
        uri: Some(junk.to_string_lossy().into_owned()),
        ..dummy(320, 240, 30)
    };
    let error = OpenNiDepth::new(config).start(&Clock::Monotonic).unwrap_err();
    assert!(matches!(error, CaptureError::Recording { .. }), "{error:?}");
    let cause = std::error::Error::source(&error).expect("a cause").to_string();
    assert!(cause.contains("oniDeviceOpen"), "{cause}");
}

#[test]
fn the_wrapper_keeps_openni_error_text() {
    let _guard = serial();
    let error = ni::Device::open("no-such-device://0").unwrap_err();
    let ni::Error::Call { call, status, detail } = &error else {
        panic!("{error:?}");
    };
    assert_eq!(*call, "oniDeviceOpen");
    assert_eq!(*status, ni::Status::NoDevice);
    assert!(detail.contains("no-such-device://0"), "{detail}");

    let device = ni::Device::open("Dummy").unwrap();
    assert!(!device.is_file());
    assert!(device.serial().is_err(), "Dummy has no serial property");
    let modes = device.sensor_info(ni::SensorType::Depth).unwrap().modes;
    assert_eq!(
        modes,
        [ni::VideoMode {
            pixel_format: ni::PixelFormat::Depth1Mm,
            width: 320,
            height: 240,
            fps: 30
        }]
    );
    assert!(device.sensor_info(ni::SensorType::Ir).is_none());
}

/// Records from Dummy while reading it; returns the live frames read as `(index, time in µs,
/// data)`, a few more after the recording stopped so that every recorded frame is among them.
fn record_dummy(path: &Path, frames: usize) -> Vec<(u64, u64, Vec<u16>)> {
    let device = ni::Device::open("Dummy").expect("opening Dummy");
    let mut stream = device.create_depth_stream().expect("a depth stream");
    assert!(
        stream.cropping().is_none(),
        "Dummy has no cropping: the recorder fixes the file"
    );
    stream.start().expect("starting Dummy");
    let mut recorder = ni::Recorder::create(path).expect("a recorder");
    recorder.attach(&stream, false).expect("attaching the stream");
    recorder.start().expect("starting the recorder");

    let mut live = Vec::new();
    let mut frame = ni::DepthFrame::default();
    let mut read = |live: &mut Vec<(u64, u64, Vec<u16>)>| {
        let outcome = stream
            .read_frame(Duration::from_secs(2), &mut frame)
            .expect("reading Dummy");
        assert_eq!(outcome, ni::ReadOutcome::Frame);
        assert_eq!(frame.pixel_format, ni::PixelFormat::Depth1Mm);
        live.push((frame.index, frame.timestamp_us, frame.data.clone()));
    };
    for _ in 0..frames {
        read(&mut live);
    }
    recorder.finish().expect("closing the recording");
    for _ in 0..3 {
        read(&mut live);
    }
    stream.stop();
    live
}

#[test]
fn a_recording_plays_back_every_frame_then_finishes() {
    let _guard = serial();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("dummy.oni");
    let live = record_dummy(&path, 15);

    let config = OpenNiConfig {
        uri: Some(path.to_string_lossy().into_owned()),
        serial: None,
        width: 320,
        height: 240,
        fps: 30,
    };
    let mut source = OpenNiDepth::new(config);
    let clock = Clock::replay(7);
    source.start(&clock).unwrap();
    let meta = source.meta();
    assert_eq!((meta.width, meta.height, meta.fps), (320, 240, 30.0));
    assert_eq!(meta.model, "oni File");
    let recorded = source.recording_frames().expect("a recording knows its length");
    assert!((12..=18).contains(&recorded), "{recorded} frames recorded");

    let mut played = Vec::new();
    for _ in 0..200 {
        if source.finished() {
            break;
        }
        played.extend(source.next_frame(Duration::from_millis(500)).unwrap());
    }
    assert!(source.finished(), "the end of the file was not seen");
    assert_eq!(source.next_frame(Duration::from_millis(1)).unwrap(), None);
    assert_eq!(played.len() as u64, recorded, "every recorded frame plays back once");

    // The recorder numbers frames from 1 and starts its clock at 0: the live frames shifted.
    let first = live
        .iter()
        .position(|(_, _, data)| *data == played[0].data)
        .expect("the first played frame was read live");
    let (first_index, first_us, _) = live[first];
    for (i, frame) in played.iter().enumerate() {
        let (index, us, data) = &live[first + i];
        assert_eq!(frame.stamp.seq, i as u64 + 1);
        assert_eq!(frame.stamp.seq, index - first_index + 1);
        assert_eq!(frame.stamp.device_ns, (us - first_us) * 1000);
        assert_eq!(frame.stamp.host_ns, 7);
        assert_eq!(&frame.data, data, "frame {i} differs");
    }
    source.stop().unwrap();
}

#[test]
fn the_device_list_names_the_backend_and_the_uri() {
    let _guard = serial();
    // Dummy is listed once it has been opened in this process.
    drop(ni::Device::open("Dummy").unwrap());
    let devices = list_devices().unwrap();
    let dummy = devices.iter().find(|d| d.id == "Dummy").expect("Dummy listed");
    assert_eq!(dummy.backend, "openni2");
    assert_eq!(dummy.model, "Table Tennis");
    assert_eq!(dummy.serial, "");
    assert!(dummy.details.contains("usb 0000:0000"), "{}", dummy.details);
    assert!(devices.iter().all(|d| d.backend == "openni2" && !d.id.is_empty()));
}
