//! Session directories: writing and reading back, surviving a killed writer and damaged
//! bytes, rejecting what is not a session, and writing byte-identical files for equal input.

use mousepose::core::frame::{ColorFrame, DepthFrame, PixelFormat, Stamp};
use mousepose::core::geometry::Rig;
use mousepose::core::pose::JointPositions;
use mousepose::io::session::{
    BackendName, CameraMeta, CameraRole, FrameFormat, SessionError, SessionEvent, SessionMeta, SessionReader,
    SessionSource, SessionSummary, SessionWriter, Truth,
};
use mousepose::io::store::{self, HeaderFault, IndexStatus, Kind, RecordReader, RecordWriter, SkipReason, StoreError};
use nalgebra::Point3;
use std::fs;
use std::path::{Path, PathBuf};

const DEPTH_FRAMES: u64 = 20;
const COLOR_FRAMES: u64 = 20;

fn stamp(seq: u64, base_ns: u64) -> Stamp {
    Stamp {
        seq,
        device_ns: base_ns + seq * 33_333_333,
        host_ns: 1_000_000_000 + seq * 33_366_000 + base_ns / 7,
    }
}

/// A 640x480 depth image: a floor 600 mm away with a gentle slope and texture, a mouse-sized
/// blob that moves with `seq`, and holes with no reading.
fn depth_frame(seq: u64) -> DepthFrame {
    let (w, h) = (640u32, 480u32);
    let mut data = Vec::with_capacity((w * h) as usize);
    let (bx, by) = (100.0 + 20.0 * seq as f64, 240.0 + 5.0 * seq as f64);
    for y in 0..h {
        for x in 0..w {
            let mut z =
                600.0 + 0.01 * f64::from(x) - 0.02 * f64::from(y) + f64::from((x * 7 + y * 13 + seq as u32) % 5);
            let d2 = (f64::from(x) - bx).powi(2) / 900.0 + (f64::from(y) - by).powi(2) / 400.0;
            if d2 < 1.0 {
                z -= 30.0 * (1.0 - d2).sqrt();
            }
            let hole = (x + y * 3 + seq as u32 * 11) % 97 == 0;
            data.push(if hole { 0 } else { z.round() as u16 });
        }
    }
    DepthFrame {
        stamp: stamp(seq, 5_000),
        width: w,
        height: h,
        data,
    }
}

/// Colour frames alternate between a 640x512 Bayer mosaic and a 320x256 RGB image.
fn color_frame(seq: u64) -> ColorFrame {
    let (format, w, h) = if seq % 2 == 0 {
        (PixelFormat::BayerRg8, 640, 512)
    } else {
        (PixelFormat::Rgb8, 320, 256)
    };
    let bpp = format.bytes_per_pixel() as u32;
    let mut data = Vec::with_capacity(ColorFrame::expected_len(w, h, format));
    for y in 0..h {
        for x in 0..w * bpp {
            let v = (x / 3 + y / 2 + seq as u32 * 9) % 256;
            let speckle = (x * 31 + y * 17 + seq as u32) % 13;
            data.push((v + speckle) as u8);
        }
    }
    ColorFrame {
        stamp: stamp(seq, 900),
        width: w,
        height: h,
        format,
        data,
    }
}

fn joints(seq: u64) -> JointPositions {
    std::array::from_fn(|j| {
        let j = j as f64;
        Point3::new(
            j * 4.1 + seq as f64 * 0.37,
            -j * 1.0 / 3.0,
            12.5 + (seq as f64 * 0.1 + j).sin(),
        )
    })
}

fn camera(role: CameraRole, width: u32, height: u32, pixel_format: FrameFormat) -> CameraMeta {
    CameraMeta {
        role,
        backend: BackendName::SYNTHETIC,
        model: format!("synthetic {role}"),
        serial: format!("SYN-{role}-0001"),
        firmware: String::new(),
        width,
        height,
        pixel_format,
        fps: 30.0,
    }
}

fn meta(with_color: bool) -> SessionMeta {
    let mut cameras = vec![camera(CameraRole::Depth, 640, 480, FrameFormat::Depth16)];
    if with_color {
        cameras.push(camera(
            CameraRole::Color,
            640,
            512,
            FrameFormat::Color(PixelFormat::BayerRg8),
        ));
    }
    let mut meta = SessionMeta::new("2026-11-21T20:00:00Z", SessionSource::Synthetic, cameras);
    meta.notes = "a test session\nwith two lines".into();
    meta.rig = Some(Rig::default_rig().with_color_binning(2));
    let mut synthetic = toml::Table::new();
    synthetic.insert("seed".into(), toml::Value::Integer(7));
    synthetic.insert("behaviour".into(), toml::Value::String("rearing".into()));
    meta.synthetic = Some(synthetic);
    meta
}

fn events() -> Vec<SessionEvent> {
    vec![
        SessionEvent::SessionStarted { host_ns: 1_000 },
        SessionEvent::CameraOpened {
            host_ns: 2_000,
            role: CameraRole::Depth,
            model: "synthetic depth".into(),
            serial: "SYN-depth-0001".into(),
        },
        SessionEvent::CameraOpened {
            host_ns: 2_500,
            role: CameraRole::Color,
            model: "synthetic color".into(),
            serial: "SYN-color-0001".into(),
        },
        SessionEvent::FramesDropped {
            host_ns: 3_000,
            role: CameraRole::Color,
            seq_from: 4,
            count: 2,
            reason: "queue full, \"writer\" slow".into(),
        },
        SessionEvent::CameraDisconnected {
            host_ns: 4_000,
            role: CameraRole::Depth,
            reason: "usb reset".into(),
        },
        SessionEvent::Note {
            host_ns: 5_000,
            message: "ünïcode ok".into(),
        },
    ]
}

fn pair(seq: u64) -> Option<u64> {
    (seq % 5 != 3).then_some(seq)
}

/// A full session: every depth and colour frame, the events above and the truth; finished
/// (with its summary returned) or left as a killed writer would leave it.
fn write_full(dir: &Path, finish: bool) -> Result<Option<SessionSummary>, SessionError> {
    let mut w = SessionWriter::create(dir, &meta(true))?;
    let events = events();
    for seq in 0..DEPTH_FRAMES.max(COLOR_FRAMES) {
        if let Some(e) = events.get(seq as usize) {
            w.log_event(e)?;
        }
        if seq < DEPTH_FRAMES {
            w.write_depth(&depth_frame(seq))?;
            w.write_truth(seq, stamp(seq, 5_000).device_ns, &joints(seq))?;
            w.write_truth_pair(seq, pair(seq))?;
        }
        if seq < COLOR_FRAMES {
            w.write_color(&color_frame(seq))?;
        }
    }
    if finish { w.finish().map(Some) } else { Ok(None) }
}

fn depth_path(dir: &Path) -> PathBuf {
    dir.join("depth").join("frames.mpstore")
}

fn read_depth(r: &SessionReader) -> Vec<DepthFrame> {
    r.depth_frames().collect::<Result<Vec<_>, _>>().expect("depth frames")
}

/// Offsets of the depth records, from the index the writer left.
fn depth_offsets(dir: &Path) -> Vec<u64> {
    store::read_index(dir.join("depth").join("index.mpindex"))
        .expect("depth index")
        .entries
        .iter()
        .map(|e| e.1)
        .collect()
}

#[test]
fn a_full_session_reads_back_identically() {
    let dir = tempfile::tempdir().unwrap();
    let summary = write_full(dir.path(), true).unwrap().unwrap();
    assert_eq!(
        (summary.depth_frames, summary.color_frames),
        (DEPTH_FRAMES, COLOR_FRAMES)
    );
    assert_eq!(summary.events, events().len() as u64 + 1);
    assert_eq!(summary.depth_bytes, fs::metadata(depth_path(dir.path())).unwrap().len());
    // Compression pays: delta + zstd stores the depth images in well under their raw size.
    assert!(
        summary.depth_bytes < DEPTH_FRAMES * 640 * 480 * 2 / 3,
        "{}",
        summary.depth_bytes
    );
    for file in [
        "session.toml",
        "events.jsonl",
        "depth/frames.mpstore",
        "depth/index.mpindex",
        "depth/timestamps.csv",
        "color/frames.mpstore",
        "color/index.mpindex",
        "color/timestamps.csv",
        "truth/joints.csv",
        "truth/pairs.csv",
    ] {
        assert!(dir.path().join(file).is_file(), "{file} missing");
    }

    let r = SessionReader::open(dir.path()).unwrap();
    assert_eq!(r.meta(), &meta(true));
    assert!(matches!(r.index_status(CameraRole::Depth), Some(IndexStatus::Loaded)));
    assert!(matches!(r.index_status(CameraRole::Color), Some(IndexStatus::Loaded)));
    assert_eq!(
        (r.depth_count(), r.color_count()),
        (DEPTH_FRAMES as usize, COLOR_FRAMES as usize)
    );
    assert_eq!(read_depth(&r), (0..DEPTH_FRAMES).map(depth_frame).collect::<Vec<_>>());
    let colors = r.color_frames().unwrap().collect::<Result<Vec<_>, _>>().unwrap();
    assert_eq!(colors, (0..COLOR_FRAMES).map(color_frame).collect::<Vec<_>>());
    for i in [0, 7, 19] {
        assert_eq!(r.depth_frame(i).unwrap(), depth_frame(i as u64));
        assert_eq!(r.color_frame(i).unwrap(), color_frame(i as u64));
    }
    assert_eq!(r.seqs(CameraRole::Depth), (0..DEPTH_FRAMES).collect::<Vec<_>>());
    assert!(matches!(
        r.depth_frame(20),
        Err(SessionError::OutOfRange {
            index: 20,
            count: 20,
            ..
        })
    ));
    assert_eq!(
        r.timestamps(CameraRole::Depth).unwrap(),
        (0..DEPTH_FRAMES).map(|s| stamp(s, 5_000)).collect::<Vec<_>>()
    );
    assert_eq!(
        r.timestamps(CameraRole::Color).unwrap(),
        (0..COLOR_FRAMES).map(|s| stamp(s, 900)).collect::<Vec<_>>()
    );

    let mut expected = events();
    let last_host_ns = (0..DEPTH_FRAMES).map(|s| stamp(s, 5_000).host_ns).max().unwrap();
    expected.push(SessionEvent::SessionEnded {
        host_ns: last_host_ns,
        depth_frames: DEPTH_FRAMES,
        color_frames: COLOR_FRAMES,
    });
    assert_eq!(r.events().unwrap(), expected);
    assert!(r.complete());

    let truth = r.truth().unwrap().unwrap();
    assert_eq!(
        truth,
        Truth {
            joints: (0..DEPTH_FRAMES)
                .map(|s| (s, stamp(s, 5_000).device_ns, joints(s)))
                .collect(),
            pairs: (0..DEPTH_FRAMES).map(|s| (s, pair(s))).collect(),
            others: Vec::new(),
        }
    );
    assert!(r.damage().is_clean());
    assert!(r.verify().unwrap().is_clean());

    let header = fs::read_to_string(dir.path().join("truth/joints.csv")).unwrap();
    let header = header.lines().next().unwrap();
    assert!(
        header.starts_with("depth_seq,time_ns,snout_x,snout_y,snout_z,head_x,"),
        "{header}"
    );
    assert!(header.ends_with(",right_hind_paw_z"), "{header}");
    let pairs = fs::read_to_string(dir.path().join("truth/pairs.csv")).unwrap();
    assert!(pairs.starts_with("depth_seq,color_seq\n0,0\n1,1\n2,2\n3,\n"), "{pairs}");
}

#[test]
fn a_killed_writer_leaves_every_complete_frame_readable() {
    let dir = tempfile::tempdir().unwrap();
    write_full(dir.path(), false).unwrap();
    // What SIGKILL in the middle of writing frame 19 leaves: the file ends inside its record.
    let path = depth_path(dir.path());
    let len = fs::metadata(&path).unwrap().len();
    let index = dir.path().join("depth").join("index.mpindex");
    assert!(!index.exists(), "an unfinished session has no index");
    let mut r = RecordReader::open(&path, Kind::DepthFrames).unwrap();
    let offsets: Vec<u64> = r.records().map(|rec| rec.unwrap().offset).collect();
    let last = offsets[19];
    // Shortest last: each cut shortens the file further.
    for cut in [len - 1, (last + len) / 2, last + 40, last + 16, last + 3] {
        let file = fs::OpenOptions::new().write(true).open(&path).unwrap();
        file.set_len(cut).unwrap();
        drop(file);
        let r = SessionReader::open(dir.path()).unwrap();
        assert!(matches!(r.index_status(CameraRole::Depth), Some(IndexStatus::Missing)));
        assert_eq!(r.depth_count(), 19, "cut at {cut}");
        assert_eq!(r.damage().depth.truncated_tail_bytes, cut - last);
        assert!(r.damage().depth.skipped.is_empty());
        let mut frames = r.depth_frames();
        let read: Vec<DepthFrame> = frames.by_ref().map(Result::unwrap).collect();
        assert_eq!(read, (0..19).map(depth_frame).collect::<Vec<_>>());
        assert_eq!(frames.damage().truncated_tail_bytes, cut - last);
        assert_eq!(r.depth_frame(18).unwrap(), depth_frame(18));
        assert_eq!(r.color_count(), COLOR_FRAMES as usize);
    }
    // A line cut short in the event log and the truth is dropped, the rest kept.
    let events_path = dir.path().join("events.jsonl");
    let mut text = fs::read_to_string(&events_path).unwrap();
    text.push_str(r#"{"kind":"note","host_ns":9,"mess"#);
    fs::write(&events_path, text).unwrap();
    let joints_path = dir.path().join("truth/joints.csv");
    let mut text = fs::read_to_string(&joints_path).unwrap();
    text.push_str("20,123,4.5");
    fs::write(&joints_path, text).unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert_eq!(r.events().unwrap(), events());
    assert!(!r.complete());
    assert_eq!(r.truth().unwrap().unwrap().joints.len(), DEPTH_FRAMES as usize);
}

#[test]
fn a_damaged_payload_byte_skips_that_frame_only() {
    let dir = tempfile::tempdir().unwrap();
    write_full(dir.path(), true).unwrap();
    let path = depth_path(dir.path());
    let offsets = depth_offsets(dir.path());
    let mut bytes = fs::read(&path).unwrap();
    bytes[offsets[7] as usize + 16 + 1000] ^= 0x10;
    fs::write(&path, &bytes).unwrap();

    // The index still matches the file's length, so it is used; the damage shows on reading.
    let r = SessionReader::open(dir.path()).unwrap();
    assert_eq!(r.depth_count(), 20);
    let mut frames = r.depth_frames();
    let read: Vec<DepthFrame> = frames.by_ref().map(Result::unwrap).collect();
    let expected: Vec<DepthFrame> = (0..DEPTH_FRAMES).filter(|&s| s != 7).map(depth_frame).collect();
    assert_eq!(read, expected);
    let damage = frames.damage();
    assert_eq!(damage.skipped_records(), 1);
    assert_eq!(damage.skipped[0].offset, offsets[7]);
    assert_eq!(damage.skipped[0].reason, SkipReason::PayloadCrc);
    let err = r.depth_frame(7).unwrap_err();
    assert!(matches!(err, SessionError::Store(StoreError::Corrupt { offset, .. }) if offset == offsets[7]));
    assert!(
        mousepose::core::error_chain(&err).contains("payload checksum mismatch"),
        "{}",
        mousepose::core::error_chain(&err)
    );
    assert_eq!(r.depth_frame(8).unwrap(), depth_frame(8));
    assert_eq!(r.verify().unwrap().depth.skipped_records(), 1);

    // Without the index the damaged frame is left out of the rebuilt one.
    fs::remove_file(dir.path().join("depth/index.mpindex")).unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert_eq!(r.depth_count(), 19);
    assert_eq!(r.damage().depth.skipped_records(), 1);
    assert_eq!(r.depth_frame(7).unwrap(), depth_frame(8));
}

#[test]
fn a_damaged_length_is_not_trusted_and_reading_resynchronises() {
    let dir = tempfile::tempdir().unwrap();
    write_full(dir.path(), true).unwrap();
    let path = depth_path(dir.path());
    let offsets = depth_offsets(dir.path());
    let original = fs::read(&path).unwrap();

    // A flipped length: the header checksum fails.
    let mut bytes = original.clone();
    let at = offsets[5] as usize + 4;
    bytes[at..at + 4].copy_from_slice(&0xffff_fff0u32.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    let mut frames = r.depth_frames();
    let seqs: Vec<u64> = frames.by_ref().map(|f| f.unwrap().stamp.seq).collect();
    assert_eq!(seqs, (0..DEPTH_FRAMES).filter(|&s| s != 5).collect::<Vec<_>>());
    let damage = frames.damage();
    assert_eq!(damage.skipped_records(), 1);
    assert_eq!(damage.skipped[0].reason, SkipReason::Header(HeaderFault::BadHeaderCrc));
    assert_eq!(damage.skipped[0].len, offsets[6] - offsets[5]);
    assert_eq!(damage.truncated_tail_bytes, 0);

    // A huge length with a checksum that verifies (a forged header): over the cap, skipped.
    let mut bytes = original;
    let at = offsets[5] as usize;
    bytes[at + 4..at + 8].copy_from_slice(&u32::MAX.to_le_bytes());
    let crc = crc32fast::hash(&bytes[at..at + 12]);
    bytes[at + 12..at + 16].copy_from_slice(&crc.to_le_bytes());
    fs::write(&path, &bytes).unwrap();
    fs::remove_file(dir.path().join("depth/index.mpindex")).unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert_eq!(r.depth_count(), 19);
    assert_eq!(
        r.damage().depth.skipped[0].reason,
        SkipReason::Header(HeaderFault::LengthOverLimit)
    );
    assert_eq!(read_depth(&r).len(), 19);
}

#[test]
fn an_intact_record_that_is_not_a_valid_frame_is_named() {
    let dir = tempfile::tempdir().unwrap();
    write_full(dir.path(), true).unwrap();
    // Rewrite the depth file with a good frame, a frame whose header lies about its size,
    // and a good frame.
    let path = depth_path(dir.path());
    let good: Vec<Vec<u8>> = {
        let mut r = RecordReader::open(&path, Kind::DepthFrames).unwrap();
        r.records().take(3).map(|rec| rec.unwrap().payload).collect()
    };
    let mut bad = good[1].clone();
    bad[24..26].copy_from_slice(&641u16.to_le_bytes());
    fs::remove_file(&path).unwrap();
    fs::remove_file(dir.path().join("depth/index.mpindex")).unwrap();
    let mut w = RecordWriter::create(&path, Kind::DepthFrames).unwrap();
    for payload in [&good[0], &bad, &good[2]] {
        w.append(payload).unwrap();
    }
    w.sync().unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    let items: Vec<_> = r.depth_frames().collect();
    assert_eq!(items.len(), 3);
    assert_eq!(items[0].as_ref().unwrap(), &depth_frame(0));
    assert_eq!(items[2].as_ref().unwrap(), &depth_frame(2));
    let err = items[1].as_ref().unwrap_err();
    let message = mousepose::core::error_chain(err);
    assert!(
        message.starts_with(&format!("{}: frame seq 1 at offset ", path.display())),
        "{message}"
    );
    assert!(
        message.contains("641x480 depth16 takes 615360 bytes but the header says 614400"),
        "{message}"
    );
    assert!(matches!(r.depth_frame(1), Err(SessionError::Frame { .. })));
}

#[test]
fn what_is_not_a_session_is_rejected_clearly() {
    let dir = tempfile::tempdir().unwrap();

    // No session.toml.
    let err = SessionReader::open(dir.path()).unwrap_err();
    let toml_path = dir.path().join("session.toml");
    assert!(
        mousepose::core::error_chain(&err).starts_with(&format!("cannot read {}: ", toml_path.display())),
        "{}",
        mousepose::core::error_chain(&err)
    );

    write_full(dir.path(), true).unwrap();
    let original = fs::read_to_string(&toml_path).unwrap();

    // A newer format version.
    fs::write(&toml_path, original.replace("format_version = 1", "format_version = 2")).unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("{}: unsupported session format version 2", toml_path.display())
    );

    // Another format.
    fs::write(&toml_path, original.replace("mousepose-session", "other-thing")).unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert!(err.to_string().contains("not a mousepose session"), "{err}");

    // An unknown key.
    fs::write(&toml_path, original.replace("notes = ", "frame_rate = 3\nnotes = ")).unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert!(matches!(err, SessionError::Meta { .. }));
    assert!(
        mousepose::core::error_chain(&err).contains("unknown field `frame_rate`"),
        "{}",
        mousepose::core::error_chain(&err)
    );
    // ...also inside a camera.
    fs::write(&toml_path, original.replacen("fps = ", "gain = 2.0\nfps = ", 1)).unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert!(
        mousepose::core::error_chain(&err).contains("unknown field `gain`"),
        "{}",
        mousepose::core::error_chain(&err)
    );

    // A colour camera claiming depth pixels.
    fs::write(
        &toml_path,
        original.replace("pixel_format = \"bayer_rg8\"", "pixel_format = \"depth16\""),
    )
    .unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert!(
        err.to_string()
            .ends_with("the color camera can not have pixel format depth16"),
        "{err}"
    );
    fs::write(&toml_path, &original).unwrap();

    // Foreign files in place of the frames.
    let path = depth_path(dir.path());
    let png = b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x01\0\0\0\x01\x08\x02\0\0\0\x90wS\xde";
    for foreign in [&png[..], b"seq,device_ns,host_ns\n1,2,3\n", b""] {
        fs::write(&path, foreign).unwrap();
        let err = SessionReader::open(dir.path()).unwrap_err();
        assert_eq!(
            err.to_string(),
            format!("{}: not a mousepose record file", path.display())
        );
    }
    // Colour frames in place of depth frames.
    fs::copy(dir.path().join("color/frames.mpstore"), &path).unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("{}: holds colour frames, expected depth frames", path.display())
    );
    fs::remove_file(&path).unwrap();
    let err = SessionReader::open(dir.path()).unwrap_err();
    assert!(
        err.to_string().starts_with(&format!("cannot open {}", path.display())),
        "{err}"
    );
}

#[test]
fn writing_needs_an_empty_directory_and_a_declared_camera() {
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("stray.txt"), "x").unwrap();
    let err = SessionWriter::create(dir.path(), &meta(false)).unwrap_err();
    assert!(matches!(err, SessionError::NotEmpty { .. }), "{err}");
    let missing = dir.path().join("nope");
    assert!(matches!(
        SessionWriter::create(&missing, &meta(false)),
        Err(SessionError::Io { .. })
    ));

    let dir = tempfile::tempdir().unwrap();
    let mut w = SessionWriter::create(dir.path(), &meta(false)).unwrap();
    assert!(!dir.path().join("color").exists());
    let err = w.write_color(&color_frame(0)).unwrap_err();
    assert!(matches!(
        err,
        SessionError::NoCamera {
            role: CameraRole::Color,
            ..
        }
    ));
    let mut bad = depth_frame(0);
    bad.data.pop();
    let err = w.write_depth(&bad).unwrap_err();
    assert!(
        mousepose::core::error_chain(&err).contains("cannot encode frame seq 0"),
        "{}",
        mousepose::core::error_chain(&err)
    );
    w.write_depth(&depth_frame(0)).unwrap();
    w.finish().unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert!(r.color_frames().is_none());
    assert_eq!((r.depth_count(), r.color_count()), (1, 0));
    assert!(matches!(r.color_frame(0), Err(SessionError::NoCamera { .. })));
    assert!(r.truth().unwrap().is_none());
    assert!(r.damage().color.is_none());
}

#[test]
fn empty_sessions_are_readable() {
    for finish in [true, false] {
        let dir = tempfile::tempdir().unwrap();
        let w = SessionWriter::create(dir.path(), &meta(true)).unwrap();
        if finish {
            w.finish_at(42).unwrap();
        } else {
            drop(w);
        }
        let r = SessionReader::open(dir.path()).unwrap();
        assert_eq!((r.depth_count(), r.color_count()), (0, 0));
        assert_eq!(r.depth_frames().count(), 0);
        assert_eq!(r.color_frames().unwrap().count(), 0);
        assert!(r.damage().is_clean());
        assert_eq!(r.complete(), finish);
        let expected = if finish {
            vec![SessionEvent::SessionEnded {
                host_ns: 42,
                depth_frames: 0,
                color_frames: 0,
            }]
        } else {
            vec![]
        };
        assert_eq!(r.events().unwrap(), expected);
        assert!(r.timestamps(CameraRole::Depth).unwrap().is_empty());
    }
}

#[test]
fn missing_invalid_or_stale_indexes_are_rebuilt() {
    let dir = tempfile::tempdir().unwrap();
    write_full(dir.path(), true).unwrap();
    let index = dir.path().join("color/index.mpindex");

    fs::remove_file(&index).unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert!(matches!(r.index_status(CameraRole::Color), Some(IndexStatus::Missing)));
    assert!(matches!(r.index_status(CameraRole::Depth), Some(IndexStatus::Loaded)));
    assert_eq!(r.color_count(), COLOR_FRAMES as usize);
    assert_eq!(r.color_frame(13).unwrap(), color_frame(13));

    fs::write(&index, b"MPINDEX\0garbage").unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert!(matches!(
        r.index_status(CameraRole::Color),
        Some(IndexStatus::Invalid(_))
    ));
    assert_eq!(r.color_count(), COLOR_FRAMES as usize);
    assert_eq!(r.color_frame(19).unwrap(), color_frame(19));

    // An index written when the file held five frames fewer.
    let mut reader = RecordReader::open(dir.path().join("color/frames.mpstore"), Kind::ColorFrames).unwrap();
    let entries: Vec<(u64, u64)> = reader
        .records()
        .map(|rec| rec.unwrap())
        .map(|rec| (0, rec.offset))
        .collect();
    store::write_index(&index, entries[15].1, &entries[..15]).unwrap();
    let r = SessionReader::open(dir.path()).unwrap();
    assert!(matches!(
        r.index_status(CameraRole::Color),
        Some(IndexStatus::Stale { .. })
    ));
    assert_eq!(r.color_count(), COLOR_FRAMES as usize);
    assert_eq!(r.seqs(CameraRole::Color), (0..COLOR_FRAMES).collect::<Vec<_>>());
    assert_eq!(r.color_frame(17).unwrap(), color_frame(17));
}

#[test]
fn equal_input_gives_byte_identical_sessions() {
    let a = tempfile::tempdir().unwrap();
    let b = tempfile::tempdir().unwrap();
    write_full(a.path(), true).unwrap();
    write_full(b.path(), true).unwrap();
    let mut files = Vec::new();
    collect_files(a.path(), a.path(), &mut files);
    files.sort();
    assert_eq!(files.len(), 10, "{files:?}");
    for file in files {
        let (x, y) = (
            fs::read(a.path().join(&file)).unwrap(),
            fs::read(b.path().join(&file)).unwrap(),
        );
        assert!(x == y, "{} differs", file.display());
    }
}

fn collect_files(root: &Path, dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in fs::read_dir(dir).expect("session directory") {
        let path = entry.expect("directory entry").path();
        if path.is_dir() {
            collect_files(root, &path, out);
        } else {
            out.push(path.strip_prefix(root).expect("under root").to_path_buf());
        }
    }
}
