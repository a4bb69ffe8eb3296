//! The V4L2 colour source (negotiation, timestamps, conversion and buffer checks on fixtures
//! made from the V4L2 specification, since the test machines have no camera) and the MoSeq
//! recording reader (small recordings written to a temporary directory).

mod moseq {
    use mousepose::core::frame::DepthFrame;
    use mousepose::runtime::capture::{CaptureError, Clock, FrameSource};
    use mousepose::runtime::recording::moseq::{MoseqConfig, MoseqDepth, MoseqError, MoseqKind};
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
        std::fs::write(dir.join("depth.dat"), bytes).expect("writes depth.dat");
    }

    fn write_metadata(dir: &Path) {
        let json = format!(r#"{{"SubjectName": "m1", "DepthResolution": [{W}, {H}], "IsLittleEndian": true}}"#);
        std::fs::write(dir.join("metadata.json"), json).expect("writes metadata.json");
    }

    /// Two columns: device time and system time, in milliseconds.
    fn write_ts(dir: &Path, n: usize) {
        let text: String = (0..n)
            .map(|i| {
                format!(
                    "{:.4} {}\n",
                    1000.0 + i as f64 * 33.3333,
                    1_700_000_000_000u64 + i as u64 * 33
                )
            })
            .collect();
        std::fs::write(dir.join("depth_ts.txt"), text).expect("writes depth_ts.txt");
    }

    fn read_all(source: &mut MoseqDepth) -> Vec<DepthFrame> {
        source.start(&Clock::replay(0)).expect("starts");
        let mut out = Vec::new();
        // Bounded so that a bug cannot hang the test.
        for _ in 0..100 {
            if source.finished() {
                break;
            }
            if let Some(frame) = source.next_frame(Duration::from_secs(10)).expect("reads a frame") {
                out.push(frame);
            }
        }
        assert!(source.finished());
        assert!(source.next_frame(Duration::from_millis(10)).expect("reads").is_none());
        source.stop().expect("stops");
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
        assert_eq!(meta.backend, "moseq");
        assert_eq!((meta.width, meta.height), (W, H));
        assert!((meta.fps - 30.0).abs() < 0.01, "{}", meta.fps);
        check_frames(&read_all(&mut source));
        // A second start reads the recording again from the beginning.
        check_frames(&read_all(&mut source));
        // Single frames by seeking.
        assert_eq!(source.frame_at(2).unwrap().data, frames()[2]);
        assert!(source.frame_at(FRAMES).is_err());
        assert_eq!(source.duplicate_timestamps(), 0);
        check_range(&source);
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
            .args([
                "-nostdin", "-v", "error", "-y", "-f", "rawvideo", "-pix_fmt", "gray16le",
            ])
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
        // Single frames by seeking, in any order.
        for k in [3, 0, FRAMES - 1, 1] {
            let frame = source.frame_at(k).unwrap();
            assert_eq!(frame.data, frames()[k], "frame {k}");
            assert_eq!(frame.stamp.seq, k as u64);
        }
        assert!(source.frame_at(FRAMES).is_err());
        check_range(&source);
    }

    /// A range read on from its first frame (a `depth.avi` by one ffmpeg seeking there) gives
    /// exactly those frames; a range past the end is refused.
    fn check_range(source: &MoseqDepth) {
        for range in [1..FRAMES, 2..3, 0..FRAMES, 3..3] {
            let mut read = Vec::new();
            source
                .for_each_in(range.clone(), |f| read.push(f))
                .expect("reads the range");
            let seqs: Vec<u64> = read.iter().map(|f| f.stamp.seq).collect();
            assert_eq!(seqs, range.clone().map(|k| k as u64).collect::<Vec<_>>());
            for f in &read {
                assert_eq!(
                    f.data,
                    frames()[f.stamp.seq as usize],
                    "frame {} of {range:?}",
                    f.stamp.seq
                );
            }
        }
        assert!(source.for_each_in(1..FRAMES + 1, |_| {}).is_err());
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
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(dir.path().join("depth.dat"))
            .unwrap();
        let len = (W * H * 2) as u64 * 3 + 100;
        file.set_len(len).unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = mousepose::core::error_chain(&err);
        assert!(matches!(moseq_error(&err), MoseqError::Truncated { .. }), "{text}");
        assert!(text.contains("depth.dat"), "{text}");
        assert!(
            text.contains(&len.to_string()) && text.contains("6144-byte frame of 64x48"),
            "{text}"
        );
    }

    #[test]
    fn out_of_order_timestamps_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames()[..3]);
        write_metadata(dir.path());
        std::fs::write(dir.path().join("depth_ts.txt"), "100 5000\n133 5033\n120 5066\n").unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = mousepose::core::error_chain(&err);
        assert!(
            matches!(moseq_error(&err), MoseqError::OutOfOrder { line: 3, .. }),
            "{text}"
        );
        assert!(text.contains("depth_ts.txt\" line 3"), "{text}");
        assert!(text.contains("120") && text.contains("133"), "{text}");
    }

    #[test]
    fn missing_timestamps_are_an_error() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames());
        write_metadata(dir.path());
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = mousepose::core::error_chain(&err);
        assert!(matches!(moseq_error(&err), MoseqError::NoTimestamps { .. }), "{text}");
        assert!(
            text.contains("no timestamp file") && text.contains("depth_ts.txt"),
            "{text}"
        );
    }

    #[test]
    fn frame_and_timestamp_counts_must_agree() {
        let dir = tempfile::tempdir().unwrap();
        write_dat(dir.path(), &frames());
        write_metadata(dir.path());
        write_ts(dir.path(), FRAMES + 1);
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        let text = mousepose::core::error_chain(&err);
        assert!(
            matches!(
                moseq_error(&err),
                MoseqError::CountMismatch {
                    frames: 5,
                    stamps: 6,
                    ..
                }
            ),
            "{text}"
        );
        assert!(
            text.contains("holds 5 frames but") && text.contains("6 timestamps"),
            "{text}"
        );
    }

    #[test]
    fn empty_directory_and_bad_metadata_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        assert!(
            matches!(moseq_error(&err), MoseqError::NoDepthFile { .. }),
            "{}",
            mousepose::core::error_chain(&err)
        );
        write_dat(dir.path(), &frames());
        write_ts(dir.path(), FRAMES);
        std::fs::write(dir.path().join("metadata.json"), r#"{"DepthResolution": [64]}"#).unwrap();
        let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
        assert!(
            matches!(moseq_error(&err), MoseqError::Resolution { .. }),
            "{}",
            mousepose::core::error_chain(&err)
        );
    }

    #[test]
    fn a_depth_resolution_beyond_any_camera_is_refused_not_an_overflow() {
        // Width x height x 2 bytes overflowed 64 bits (a panic in checked builds, a wrong
        // frame size otherwise).
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("depth.dat"), b"").unwrap();
        std::fs::write(dir.path().join("depth_ts.txt"), "").unwrap();
        for resolution in ["[4294967295, 4294967295]", "[65536, 2]"] {
            std::fs::write(
                dir.path().join("metadata.json"),
                format!(r#"{{"DepthResolution": {resolution}}}"#),
            )
            .unwrap();
            let err = MoseqDepth::open(MoseqConfig::new(dir.path())).unwrap_err();
            let text = mousepose::core::error_chain(&err);
            assert!(matches!(moseq_error(&err), MoseqError::Resolution { .. }), "{text}");
            assert!(text.contains("up to 65535"), "{text}");
        }
    }
}

mod v4l2 {
    use mousepose::core::frame::PixelFormat;
    use mousepose::runtime::capture::v4l2::{
        BUF_FLAG_ERROR, BufferDecoder, BufferMeta, BufferProblem, Chosen, Conversion, LOSS_ERROR_FLAG,
        LOSS_SHORT_BUFFER, OfferedFormat, OfferedSize, V4l2Color, V4l2Config, choose_format, list_devices,
        list_devices_in, stamp_from_buffer, yuv_to_rgb,
    };
    use mousepose::runtime::capture::{CaptureError, Clock};
    use std::path::PathBuf;

    fn fixtures() -> PathBuf {
        crate::util::repo_root().join("fixtures/v4l2")
    }

    fn webcam() -> Vec<OfferedFormat> {
        let text =
            std::fs::read_to_string(fixtures().join("uvc_webcam_formats.json")).expect("reads the formats fixture");
        serde_json::from_str(&text).expect("parses the formats fixture")
    }

    fn config(width: u32, height: u32, fps: f64, format: Option<&str>) -> V4l2Config {
        V4l2Config {
            device: PathBuf::from("/dev/video0"),
            width,
            height,
            fps,
            format: format.map(str::to_owned),
        }
    }

    #[derive(serde::Deserialize)]
    struct Recorded {
        width: u32,
        height: u32,
        bytes_per_line: u32,
        buffers: Vec<RecordedBuffer>,
    }

    #[derive(serde::Deserialize)]
    struct RecordedBuffer {
        file: String,
        sequence: u32,
        timestamp_sec: i64,
        timestamp_usec: i64,
        flags: u32,
        bytesused: u32,
    }

    impl RecordedBuffer {
        fn meta(&self) -> BufferMeta {
            BufferMeta {
                sequence: self.sequence,
                timestamp_sec: self.timestamp_sec,
                timestamp_usec: self.timestamp_usec,
                flags: self.flags,
                bytesused: self.bytesused,
            }
        }

        fn data(&self) -> Vec<u8> {
            std::fs::read(fixtures().join(&self.file)).expect("reads a buffer fixture")
        }
    }

    fn recorded() -> Recorded {
        let text = std::fs::read_to_string(fixtures().join("buffers.json")).expect("reads buffers.json");
        serde_json::from_str(&text).expect("parses buffers.json")
    }

    fn yuyv(width: u32, height: u32, conversion: Conversion) -> Chosen {
        Chosen {
            fourcc: "YUYV".into(),
            width,
            height,
            interval: [1, 30],
            output: match conversion {
                Conversion::YuyvToMono8 => PixelFormat::Mono8,
                _ => PixelFormat::Rgb8,
            },
            conversion,
        }
    }

    #[test]
    fn negotiation_prefers_yuyv_over_mjpg_at_the_same_mode() {
        let chosen = choose_format(&webcam(), &config(640, 480, 30.0, None)).unwrap();
        assert_eq!(chosen.fourcc, "YUYV");
        assert_eq!((chosen.width, chosen.height, chosen.interval), (640, 480, [1, 30]));
        assert_eq!(
            (chosen.output, chosen.conversion),
            (PixelFormat::Rgb8, Conversion::YuyvToRgb8)
        );
        let slow = choose_format(&webcam(), &config(1280, 720, 7.5, None)).unwrap();
        assert_eq!((slow.fourcc.as_str(), slow.interval), ("YUYV", [2, 15]));
        assert!((slow.fps() - 7.5).abs() < 1e-9);
    }

    #[test]
    fn negotiation_prefers_lossless_formats() {
        let size = |intervals: Vec<[u32; 2]>| OfferedSize {
            width: 640,
            height: 480,
            intervals,
        };
        let offered = vec![
            OfferedFormat {
                fourcc: "YUYV".into(),
                description: String::new(),
                sizes: vec![size(vec![[1, 30]])],
            },
            OfferedFormat {
                fourcc: "GREY".into(),
                description: String::new(),
                sizes: vec![size(vec![[1001, 30000]])],
            },
            OfferedFormat {
                fourcc: "GRBG".into(),
                description: String::new(),
                sizes: vec![size(vec![[1, 30]])],
            },
        ];
        // 29.97 frames/s is within 1 % of 30.
        let chosen = choose_format(&offered, &config(640, 480, 30.0, None)).unwrap();
        assert_eq!((chosen.fourcc.as_str(), chosen.output), ("GREY", PixelFormat::Mono8));
        let chosen = choose_format(&offered, &config(640, 480, 30.0, Some("GRBG"))).unwrap();
        assert_eq!(
            (chosen.output, chosen.conversion),
            (PixelFormat::BayerGr8, Conversion::Copy)
        );
    }

    #[test]
    fn negotiation_refuses_clearly() {
        // 1280x720 at 30 frames/s exists only as MJPG, which is not decoded.
        let err = choose_format(&webcam(), &config(1280, 720, 30.0, None))
            .unwrap_err()
            .to_string();
        assert!(
            err.starts_with("no offered mode fits 1280x720@30 (only in MJPG"),
            "{err}"
        );
        assert!(err.contains("YUYV 640x480@30/24/20/15/10/7.500/5"), "{err}");
        assert!(err.contains("MJPG 1280x720@30"), "{err}");
        let err = choose_format(&webcam(), &config(640, 480, 30.0, Some("MJPG")))
            .unwrap_err()
            .to_string();
        assert!(err.contains("cannot convert MJPG"), "{err}");
        let err = choose_format(&webcam(), &config(640, 480, 30.0, Some("GREY")))
            .unwrap_err()
            .to_string();
        assert!(err.contains("does not offer GREY"), "{err}");
        let err = choose_format(&webcam(), &config(640, 480, 60.0, None))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("640x480@60 (no format offers that size and rate)"),
            "{err}"
        );
        let err = choose_format(&[], &config(640, 480, 30.0, None))
            .unwrap_err()
            .to_string();
        assert!(err.ends_with("the device offers nothing"), "{err}");
    }

    #[test]
    fn monotonic_timestamps_map_directly_others_use_the_host_clock() {
        let buffers = recorded().buffers;
        let monotonic = buffers[0].meta();
        let stamp = stamp_from_buffer(&monotonic, &Clock::Monotonic);
        assert_eq!(stamp.seq, 100);
        assert_eq!(stamp.device_ns, 5_231_400_000_000);
        assert_eq!(stamp.host_ns, 5_231_400_000_000);
        // A copied timestamp is not on the host clock: the clock at dequeue is used.
        let copied = buffers[5].meta();
        let clock = Clock::replay(77_000);
        let stamp = stamp_from_buffer(&copied, &clock);
        assert_eq!(
            (stamp.seq, stamp.device_ns, stamp.host_ns),
            (106, 1_000_250_000, 77_000)
        );
        // Unknown clock (no flag) likewise; a replay clock is never mixed with kernel time.
        let unknown = BufferMeta { flags: 0, ..monotonic };
        assert_eq!(stamp_from_buffer(&unknown, &clock).host_ns, 77_000);
        assert_eq!(stamp_from_buffer(&monotonic, &clock).host_ns, 77_000);
        // A malformed timestamp gives device_ns 0 and the host clock.
        let bad = BufferMeta {
            timestamp_usec: 2_000_000,
            ..monotonic
        };
        let stamp = stamp_from_buffer(&bad, &Clock::Monotonic);
        assert_eq!(stamp.device_ns, 0);
        assert!(stamp.host_ns > 0);
    }

    #[test]
    fn yuyv_converts_to_the_hand_computed_pixels() {
        // Y 81, U 90, V 240: C = 65, D = -38, E = 112;
        // R = (298*65 + 409*112 + 128) >> 8 = 255, G = (19370 + 3800 - 23296 + 128) >> 8 = 0,
        // B = (19370 - 19608 + 128) >> 8 < 0 -> 0.
        assert_eq!(yuv_to_rgb(81, 90, 240), [255, 0, 0]);
        // Black and white of the limited range.
        assert_eq!(yuv_to_rgb(16, 128, 128), [0, 0, 0]);
        assert_eq!(yuv_to_rgb(235, 128, 128), [255, 255, 255]);
        // Y 100, U 150, V 60: C 84, D 22, E -68: R = (25032 - 27812 + 128) >> 8 = -11 -> 0,
        // G = (25032 - 2200 + 14144 + 128) >> 8 = 144, B = (25032 + 11352 + 128) >> 8 = 142.
        assert_eq!(yuv_to_rgb(100, 150, 60), [0, 144, 142]);

        let rec = recorded();
        let buffer = &rec.buffers[0];
        let data = buffer.data();
        let rgb = BufferDecoder::new(yuyv(rec.width, rec.height, Conversion::YuyvToRgb8), rec.bytes_per_line).unwrap();
        let mut out = Vec::new();
        rgb.convert_into(&data, &buffer.meta(), &mut out).unwrap();
        assert_eq!(out.len(), 32 * 24 * 3);
        assert_eq!(&out[..6], &[255, 0, 0, 255, 0, 0]);
        // Pixel (3, 1): the second pixel of the second pair of row 1.
        let quad = &data[64 + 4..64 + 8];
        assert_eq!(&out[(32 + 3) * 3..(32 + 4) * 3], &yuv_to_rgb(quad[2], quad[1], quad[3]));

        let mono =
            BufferDecoder::new(yuyv(rec.width, rec.height, Conversion::YuyvToMono8), rec.bytes_per_line).unwrap();
        mono.convert_into(&data, &buffer.meta(), &mut out).unwrap();
        let luma: Vec<u8> = data.iter().step_by(2).copied().collect();
        assert_eq!(out, luma);
    }

    #[test]
    fn conversion_reuses_the_buffer_and_honours_the_stride() {
        let rec = recorded();
        let buffer = &rec.buffers[1];
        let data = buffer.data();
        let decoder =
            BufferDecoder::new(yuyv(rec.width, rec.height, Conversion::YuyvToRgb8), rec.bytes_per_line).unwrap();
        let mut out = Vec::with_capacity(32 * 24 * 3);
        let before = out.as_ptr();
        for _ in 0..3 {
            decoder.convert_into(&data, &buffer.meta(), &mut out).unwrap();
            assert_eq!(out.as_ptr(), before, "no reallocation");
        }
        // GREY 6x2 with 8-byte rows: the padding is dropped; the last row needs no padding.
        let grey = Chosen {
            fourcc: "GREY".into(),
            width: 6,
            height: 2,
            interval: [1, 30],
            output: PixelFormat::Mono8,
            conversion: Conversion::Copy,
        };
        let decoder = BufferDecoder::new(grey.clone(), 8).unwrap();
        let data = [1, 2, 3, 4, 5, 6, 0xEE, 0xEE, 7, 8, 9, 10, 11, 12, 0xEE, 0xEE];
        let meta = BufferMeta {
            bytesused: 14,
            ..BufferMeta::default()
        };
        decoder.convert_into(&data, &meta, &mut out).unwrap();
        assert_eq!(out, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
        let short = BufferMeta { bytesused: 13, ..meta };
        assert_eq!(
            decoder.convert_into(&data, &short, &mut out),
            Err(BufferProblem::Short {
                bytesused: 13,
                needed: 14
            })
        );
        assert!(out.is_empty());
        let overlong = BufferMeta { bytesused: 17, ..meta };
        assert!(matches!(
            decoder.convert_into(&data, &overlong, &mut out),
            Err(BufferProblem::Overlong { .. })
        ));
        let err = BufferDecoder::new(grey, 5).unwrap_err().to_string();
        assert_eq!(err, "stride of 5 bytes is shorter than a 6-pixel GREY row");
    }

    #[test]
    fn short_and_erroneous_buffers_are_counted_never_returned() {
        let rec = recorded();
        let mut decoder =
            BufferDecoder::new(yuyv(rec.width, rec.height, Conversion::YuyvToRgb8), rec.bytes_per_line).unwrap();
        let clock = Clock::replay(9);
        let frames: Vec<_> = rec
            .buffers
            .iter()
            .filter_map(|b| decoder.decode(&b.data(), &b.meta(), &clock))
            .collect();
        let seqs: Vec<u64> = frames.iter().map(|f| f.stamp.seq).collect();
        // 102 was dropped by the kernel (a gap the runner counts), 104 short, 105 flagged.
        assert_eq!(seqs, [100, 101, 103, 106]);
        assert!(rec.buffers[4].flags & BUF_FLAG_ERROR != 0);
        assert_eq!(decoder.losses(), [(LOSS_SHORT_BUFFER, 1), (LOSS_ERROR_FLAG, 1)]);
        for frame in &frames {
            assert_eq!((frame.width, frame.height, frame.format), (32, 24, PixelFormat::Rgb8));
            assert_eq!(frame.data.len(), 32 * 24 * 3);
        }
    }

    #[test]
    fn opening_a_missing_device_says_so() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("video9");
        let err = V4l2Color::open(V4l2Config {
            device: missing.clone(),
            ..config(640, 480, 30.0, None)
        })
        .unwrap_err();
        assert!(matches!(err, CaptureError::NotFound { backend: "v4l2", .. }), "{err}");
        assert_eq!(
            err.to_string(),
            format!("no v4l2 camera {:?} found", missing.display().to_string())
        );

        // A file that is not a device: the driver error says what failed.
        std::fs::write(&missing, b"not a camera").unwrap();
        let err = V4l2Color::open(V4l2Config {
            device: missing.clone(),
            ..config(640, 480, 30.0, None)
        })
        .unwrap_err();
        let text = mousepose::core::error_chain(&err);
        assert!(text.contains("not a V4L2 device (VIDIOC_QUERYCAP failed)"), "{text}");
    }

    #[test]
    fn listing_devices_without_cameras_is_empty_not_an_error() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("video0"), b"").unwrap();
        std::fs::write(dir.path().join("null"), b"").unwrap();
        assert!(list_devices_in(dir.path()).is_empty());
        assert!(list_devices_in(&dir.path().join("absent")).is_empty());
        // On a machine with cameras this lists them; here it must simply not fail.
        for device in list_devices() {
            assert_eq!(device.backend, "v4l2");
        }
    }
}
