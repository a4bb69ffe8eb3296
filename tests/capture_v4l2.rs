//! The V4L2 colour source (negotiation, timestamps, conversion and buffer checks on fixtures
//! made from the V4L2 specification, since the test machines have no camera) and the MoSeq
//! recording reader (small recordings written to a temporary directory).

/// The error and its whole chain of causes, as `{:#}` prints it with anyhow.
fn chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text.push_str(": ");
        text.push_str(&cause.to_string());
        source = cause.source();
    }
    text
}

mod moseq {
    use super::chain;
    use mousepose::capture::moseq::{MoseqConfig, MoseqDepth, MoseqError, MoseqKind};
    use mousepose::capture::{CaptureError, Clock, FrameSource};
    use mousepose::frame::DepthFrame;
    use mousepose::session::meta::Backend;
    use std::path::Path;
    use std::process::Command;
    use std::time::Duration;

    const W: u32 = 64;
    const H: u32 = 48;
    const FRAMES: usize = 5;

    /// Depth values that use the whole u16 range, different in every frame and pixel.
    fn frames() -> Vec<Vec<u16>> {
        (0..FRAMES)
            .map(|f| {
                (0..(W * H) as usize)
                    .map(|i| (i as u32).wrapping_mul(2_654_435_761).wrapping_add(f as u32 * 40_503) as u16)
                    .collect()
            })
            .collect()
    }

    fn write_dat(dir: &Path, frames: &[Vec<u16>]) {
        let bytes: Vec<u8> = frames.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(dir.join("depth.dat"), bytes).unwrap();
    }

    fn write_metadata(dir: &Path) {
        let json = format!(r#"{{"SubjectName": "m1", "DepthResolution": [{W}, {H}], "IsLittleEndian": true}}"#);
        std::fs::write(dir.join("metadata.json"), json).unwrap();
    }

    /// Two columns: device time and system time, in milliseconds.
    fn write_ts(dir: &Path, n: usize) {
        let text: String = (0..n)
            .map(|i| format!("{:.4} {}\n", 1000.0 + i as f64 * 33.3333, 1_700_000_000_000u64 + i as u64 * 33))
            .collect();
        std::fs::write(dir.join("depth_ts.txt"), text).unwrap();
    }

    fn read_all(source: &mut MoseqDepth) -> Vec<DepthFrame> {
        source.start(&Clock::replay(0)).unwrap();
        let mut out = Vec::new();
        // Bounded so that a bug cannot hang the test.
        for _ in 0..100 {
            if source.finished() {
                break;
            }
            if let Some(frame) = source.next_frame(Duration::from_secs(10)).unwrap() {
                out.push(frame);
            }
        }
        assert!(source.finished());
        assert!(source.next_frame(Duration::from_millis(10)).unwrap().is_none());
        source.stop().unwrap();
        out
    }

    fn check_frames(frames: &[DepthFrame]) {
        let expected = self::frames();
        assert_eq!(frames.len(), FRAMES);
        for (i, frame) in frames.iter().enumerate() {
            assert_eq!((frame.width, frame.height), (W, H));
            assert_eq!(frame.data, expected[i], "frame {i}");
            assert_eq!(frame.stamp.seq, i as u64);
        }
        // "1033.3333" ms exactly, and the system column as host time.
        assert_eq!(frames[1].stamp.device_ns, 1_033_333_300);
        assert_eq!(frames[1].stamp.host_ns, 1_700_000_000_033_000_000);
    }

    fn moseq_error(error: &CaptureError) -> &MoseqError {
        match error {
            CaptureError::Recording { source, .. } => source.downcast_ref::<MoseqError>().expect("a MoseqError"),
            other => panic!("not a recording error: {other}"),
        }
    }

    #[test]
    fn depth_dat_reads_back_exactly() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames());
        write_metadata(dir.path());
        write_ts(dir.path(), FRAMES);
        let mut source = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap();
        assert_eq!(source.kind(), MoseqKind::Raw);
        assert_eq!(source.frame_count(), FRAMES);
        let meta = source.meta();
        assert_eq!(meta.backend, Backend::Moseq);
        assert_eq!((meta.width, meta.height), (W, H));
        assert!((meta.fps - 30.0).abs() < 0.01, "{}", meta.fps);
        check_frames(&read_all(&mut source));
        // A second start reads the recording again from the beginning.
        check_frames(&read_all(&mut source));
    }

    #[test]
    fn one_column_timestamps_are_host_and_device_time() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames()[..2]);
        std::fs::write(dir.path().join("depth_ts.txt"), "5\n38.25\n").unwrap();
        let mut config = MoseqConfig::new(dir.path());
        // No metadata.json: the default size applies.
        (config.default_width, config.default_height) = (W, H);
        let mut source = MoseqDepth::open(config).unwrap();
        let frames = read_all(&mut source);
        assert_eq!(frames[1].stamp.device_ns, 38_250_000);
        assert_eq!(frames[1].stamp.host_ns, 38_250_000);
    }

    #[test]
    fn depth_avi_ffv1_reads_back_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("frames.raw");
        let bytes: Vec<u8> = frames().iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        std::fs::write(&raw, bytes).unwrap();
        let status = Command::new("ffmpeg")
            .args(["-nostdin", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray16le"])
            .args(["-s", &format!("{W}x{H}"), "-r", "30", "-i"])
            .arg(&raw)
            .args(["-c:v", "ffv1", "-pix_fmt", "gray16le"])
            .arg(dir.path().join("depth.avi"))
            .status()
            .expect("ffmpeg runs");
        assert!(status.success());
        std::fs::remove_file(&raw).unwrap();
        write_ts(dir.path(), FRAMES);
        let mut source = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap();
        assert_eq!(source.kind(), MoseqKind::Video);
        assert_eq!(source.size(), (W, H));
        check_frames(&read_all(&mut source));
    }

    #[test]
    fn stopping_a_video_early_ends_ffmpeg() {
        let dir = tempfile::tempdir().unwrap();
        let status = Command::new("ffmpeg")
            .args(["-nostdin", "-v", "error", "-y", "-f", "lavfi", "-i"])
            .arg(format!("testsrc=size={W}x{H}:rate=30:duration=10"))
            .args(["-c:v", "ffv1", "-pix_fmt", "gray16le"])
            .arg(dir.path().join("depth.avi"))
            .status()
            .expect("ffmpeg runs");
        assert!(status.success());
        write_ts(dir.path(), 300);
        let mut source = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap();
        source.start(&Clock::replay(0)).unwrap();
        let frame = source.next_frame(Duration::from_secs(10)).unwrap().unwrap();
        assert_eq!(frame.stamp.seq, 0);
        source.stop().unwrap();
        assert!(source.next_frame(Duration::from_millis(10)).unwrap().is_none());
        // And dropping a running source does not hang either.
        source.start(&Clock::replay(0)).unwrap();
        drop(source);
    }

    #[test]
    fn truncated_depth_dat_names_file_and_sizes() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames());
        write_metadata(dir.path());
        write_ts(dir.path(), FRAMES);
        let file = std::fs::OpenOptions::new().write(true).open(dir.path().join("depth.dat")).unwrap();
        let len = (W * H * 2) as u64 * 3 + 100;
        file.set_len(len).unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = chain(&err);
        assert!(matches!(moseq_error(&err), MoseqError::Truncated { .. }), "{text}");
        assert!(text.contains("depth.dat"), "{text}");
        assert!(text.contains(&len.to_string()) && text.contains("6144-byte frame of 64x48"), "{text}");
    }

    #[test]
    fn out_of_order_timestamps_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames()[..3]);
        write_metadata(dir.path());
        std::fs::write(dir.path().join("depth_ts.txt"), "100 5000\n133 5033\n120 5066\n").unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = chain(&err);
        assert!(matches!(moseq_error(&err), MoseqError::OutOfOrder { line: 3, .. }), "{text}");
        assert!(text.contains("depth_ts.txt\" line 3"), "{text}");
        assert!(text.contains("120") && text.contains("133"), "{text}");
    }

    #[test]
    fn missing_timestamps_are_an_error() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames());
        write_metadata(dir.path());
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = chain(&err);
        assert!(matches!(moseq_error(&err), MoseqError::NoTimestamps { .. }), "{text}");
        assert!(text.contains("no timestamp file") && text.contains("depth_ts.txt"), "{text}");
    }

    #[test]
    fn frame_and_timestamp_counts_must_agree() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames());
        write_metadata(dir.path());
        write_ts(dir.path(), FRAMES + 1);
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = chain(&err);
        assert!(
            matches!(moseq_error(&err), MoseqError::CountMismatch { frames: 5, stamps: 6, .. }),
            "{text}"
        );
        assert!(text.contains("holds 5 frames but") && text.contains("6 timestamps"), "{text}");
    }

    #[test]
    fn empty_directory_and_bad_metadata_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        assert!(matches!(moseq_error(&err), MoseqError::NoDepthFile { .. }), "{}", chain(&err));
        write_dat(dir.path(), &frames());
        write_ts(dir.path(), FRAMES);
        std::fs::write(dir.path().join("metadata.json"), r#"{"DepthResolution": [64]}"#).unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        assert!(matches!(moseq_error(&err), MoseqError::Resolution { .. }), "{}", chain(&err));
    }
}
