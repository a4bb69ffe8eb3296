//! `GET /metrics`: the daemon's counters in the OpenMetrics text format (which Prometheus
//! scrapes), encoded by `prometheus-client` from what the [`Watch`] reads at scrape time. Every
//! name starts with `mousepose_`; labels are few-valued (camera, reason, stage, edge, status),
//! never a path, a message or a frame number. `docs/metrics.md` lists them.

use crate::runtime::accounting::{
    CameraSummary, DROPPED_REASONS, LOST_AFTER_RECORDING_REASONS, LOST_REASONS, NOT_RECORDED_REASONS,
};
use crate::runtime::capture::clock::monotonic_ns;
use crate::runtime::capture::supervise::{CameraState, lock};
use crate::runtime::pipeline::Histogram;
use crate::runtime::pose_record::PoseStatus;
use crate::runtime::status::Watch;
use crate::runtime::stream::lsl::{DROP_REASONS as LSL_DROP_REASONS, LslStats};
use crate::runtime::stream::{DROP_REASONS, StreamStats, Topic};
use crate::runtime::usage::{process_cpu_s, process_resident_bytes};
use prometheus_client::collector::Collector;
use prometheus_client::encoding::{DescriptorEncoder, EncodeCounterValue, EncodeMetric as _, NoLabelSet};
use prometheus_client::metrics::MetricType;
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::registry::{Registry, Unit};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// Upper bounds of the latency histograms' buckets, microseconds (exported in seconds).
const LATENCY_BOUNDS_US: [u64; 14] = [
    250, 500, 1_000, 2_000, 3_000, 5_000, 7_500, 10_000, 20_000, 50_000, 100_000, 250_000, 500_000, 1_000_000,
];

type Labels = Vec<(&'static str, String)>;

/// The text of `/metrics` now.
pub fn encode(watch: &Arc<Watch>) -> Result<String, std::fmt::Error> {
    let mut registry = Registry::default();
    registry.register_collector(Box::new(WatchCollector(Arc::clone(watch))));
    let mut text = String::new();
    prometheus_client::encoding::text::encode(&mut text, &registry)?;
    Ok(text)
}

#[derive(Debug)]
struct WatchCollector(Arc<Watch>);

/// Writes metric families one after the other.
struct Families<'a>(DescriptorEncoder<'a>);

impl Families<'_> {
    fn counter<N: EncodeCounterValue + Copy>(
        &mut self,
        name: &str,
        help: &str,
        unit: Option<&Unit>,
        samples: &[(Labels, N)],
    ) -> std::fmt::Result {
        let mut family = self.0.encode_descriptor(name, help, unit, MetricType::Counter)?;
        for (labels, value) in samples {
            ConstCounter::new(*value).encode(family.encode_family(labels)?)?;
        }
        Ok(())
    }

    fn gauge(&mut self, name: &str, help: &str, unit: Option<&Unit>, samples: &[(Labels, f64)]) -> std::fmt::Result {
        let mut family = self.0.encode_descriptor(name, help, unit, MetricType::Gauge)?;
        for (labels, value) in samples {
            ConstGauge::new(*value).encode(family.encode_family(labels)?)?;
        }
        Ok(())
    }

    fn histogram(&mut self, name: &str, help: &str, samples: &[(Labels, &Histogram)]) -> std::fmt::Result {
        let mut family = self
            .0
            .encode_descriptor(name, help, Some(&Unit::Seconds), MetricType::Histogram)?;
        for (labels, h) in samples {
            let (_, sum_us) = h.totals();
            let counts = h.counts_under(&LATENCY_BOUNDS_US);
            // The count from the same reading as the buckets: a recording between two readings
            // would set the `+Inf` bucket apart from `_count`, which a scraper refuses.
            let count = counts.iter().sum();
            let buckets: Vec<(f64, u64)> = LATENCY_BOUNDS_US
                .iter()
                .map(|&us| us as f64 / 1e6)
                .chain([f64::INFINITY])
                .zip(counts)
                .collect();
            family
                .encode_family(labels)?
                .encode_histogram::<NoLabelSet>(sum_us as f64 / 1e6, count, &buckets, None)?;
        }
        Ok(())
    }
}

fn label(key: &'static str, value: &str) -> Labels {
    vec![(key, value.to_owned())]
}

fn labels2(k1: &'static str, v1: &str, k2: &'static str, v2: &str) -> Labels {
    vec![(k1, v1.to_owned()), (k2, v2.to_owned())]
}

impl Collector for WatchCollector {
    fn encode(&self, encoder: DescriptorEncoder) -> std::fmt::Result {
        let w = &self.0;
        let mut f = Families(encoder);
        f.frame_families(w)?;
        f.camera_families(w)?;
        f.pipeline_families(w)?;
        f.pose_families(w)?;
        f.process_families(w)
    }
}

impl Families<'_> {
    /// Frames per camera: captured, paired, dropped, lost, recorded.
    fn frame_families(&mut self, w: &Watch) -> std::fmt::Result {
        let cameras = w.parts.pipeline.cameras();
        let per_camera = |get: &dyn Fn(&CameraSummary) -> u64| -> Vec<(Labels, u64)> {
            cameras
                .iter()
                .map(|(name, c)| (label("camera", name), get(c)))
                .collect()
        };
        // Every known reason from the start (at 0), then any other the sources met.
        let by_reason = |get: &dyn Fn(&CameraSummary) -> &BTreeMap<String, u64>, known: &[&str]| {
            cameras
                .iter()
                .flat_map(|(name, c)| {
                    let mut counts: BTreeMap<&str, u64> = known.iter().map(|&r| (r, 0)).collect();
                    counts.extend(get(c).iter().map(|(r, n)| (r.as_str(), *n)));
                    counts
                        .into_iter()
                        .map(|(reason, n)| (labels2("camera", name, "reason", reason), n))
                        .collect::<Vec<_>>()
                })
                .collect::<Vec<_>>()
        };
        self.counter(
            "mousepose_frames_captured",
            "Frames the camera delivered.",
            None,
            &per_camera(&|c| c.captured),
        )?;
        self.counter(
            "mousepose_frames_paired",
            "Frames processed in a depth-colour pair.",
            None,
            &per_camera(&|c| c.paired),
        )?;
        self.counter(
            "mousepose_frames_unpaired",
            "Frames processed without a partner (depth-only pairs, colour frames no depth frame claimed).",
            None,
            &per_camera(&|c| c.unpaired),
        )?;
        self.counter(
            "mousepose_frames_paired_unproven",
            "Depth frames paired at the end of the partner wait ([sync] partner_wait_ms) with the nearest colour frame in, a nearer one still possible (of frames_paired).",
            None,
            &per_camera(&|c| c.paired_unproven),
        )?;
        self.counter(
            "mousepose_frames_unpaired_unproven",
            "Depth frames sent depth-only at the end of the partner wait, a partner still possible (of frames_unpaired).",
            None,
            &per_camera(&|c| c.unpaired_unproven),
        )?;
        self.counter(
            "mousepose_frames_paired_again",
            "Depth frames paired at the end of the partner wait with the colour frame the depth frame before had, none other in the partner reach ([sync] partner_reach_ms; of frames_paired).",
            None,
            &per_camera(&|c| c.paired_again),
        )?;
        self.counter(
            "mousepose_frames_dropped",
            "Frames delivered but not processed, by reason.",
            None,
            &by_reason(&|c| &c.dropped, &DROPPED_REASONS),
        )?;
        self.counter(
            "mousepose_frames_lost_before_capture",
            "Frames the camera never delivered (gaps in its frame counter, damaged buffers), by reason.",
            None,
            &by_reason(&|c| &c.lost_before_capture, &LOST_REASONS),
        )?;
        self.counter(
            "mousepose_frames_recorded",
            "Frames written to the raw recording (it only grows: see frames_lost_after_recording).",
            None,
            &per_camera(&|c| c.recorded.unwrap_or(0)),
        )?;
        self.counter(
            "mousepose_frames_not_recorded",
            "Frames delivered but not recorded, by reason.",
            None,
            &by_reason(&|c| &c.not_recorded, &NOT_RECORDED_REASONS),
        )?;
        self.counter(
            "mousepose_frames_lost_after_recording",
            "Frames recorded, then gone from the run's directory (their chunk removed or moved away), by reason.",
            None,
            &by_reason(&|c| &c.lost_after_recording, &LOST_AFTER_RECORDING_REASONS),
        )?;
        Ok(())
    }

    /// The cameras' health: up, state, time away, outages.
    fn camera_families(&mut self, w: &Watch) -> std::fmt::Result {
        let now_ns = monotonic_ns();
        let (mut up, mut away_s, mut outages, mut states) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (name, health) in &w.parts.cameras {
            let h = lock(health);
            let state = match &h.state {
                Some(CameraState::Streaming) => "streaming",
                Some(CameraState::Away(_)) => "away",
                Some(CameraState::Opening) | None => "opening",
            };
            up.push((label("camera", name), f64::from(u8::from(state == "streaming"))));
            for s in ["opening", "streaming", "away"] {
                states.push((labels2("camera", name, "state", s), f64::from(u8::from(s == state))));
            }
            let current = h.outages.last().filter(|o| o.end_ns.is_none());
            let seconds = current.map_or(0.0, |o| now_ns.saturating_sub(o.start_ns) as f64 / 1e9);
            away_s.push((label("camera", name), seconds));
            outages.push((label("camera", name), h.outages.len() as u64));
        }
        self.gauge(
            "mousepose_camera_up",
            "1 while the camera delivers frames, 0 while it is opening or away.",
            None,
            &up,
        )?;
        self.gauge(
            "mousepose_camera_state",
            "The camera's state (1 for the current one).",
            None,
            &states,
        )?;
        self.gauge(
            "mousepose_camera_away",
            "How long the camera has been away in its current outage (0 when it is not).",
            Some(&Unit::Seconds),
            &away_s,
        )?;
        self.counter(
            "mousepose_camera_outages",
            "Times the camera went away.",
            None,
            &outages,
        )?;
        Ok(())
    }

    /// The pipeline: each stage's latency and items, end-to-end latency, the edges' queues.
    fn pipeline_families(&mut self, w: &Watch) -> std::fmt::Result {
        let stages = w.parts.pipeline.stages();
        self.histogram(
            "mousepose_stage_latency",
            "Time a stage or sink spends on one item.",
            &stages
                .iter()
                .map(|(name, s)| (label("stage", name), &s.latency))
                .collect::<Vec<_>>(),
        )?;
        self.counter(
            "mousepose_stage_items",
            "Items a stage or sink finished.",
            None,
            &stages
                .iter()
                .map(|(name, s)| (label("stage", name), s.items_out.load(Ordering::Relaxed)))
                .collect::<Vec<_>>(),
        )?;
        self.histogram(
            "mousepose_end_to_end_latency",
            "From a frame pair leaving the synchroniser to its pose row handed to the operating system.",
            &[(Vec::new(), w.parts.pipeline.end_to_end())],
        )?;
        let edges = w.parts.pipeline.edges();
        self.gauge(
            "mousepose_queue_depth",
            "Items waiting on an edge between threads (after its last send).",
            None,
            &edges
                .iter()
                .map(|(name, e)| (label("edge", name), e.depth as f64))
                .collect::<Vec<_>>(),
        )?;
        self.gauge(
            "mousepose_queue_capacity",
            "Capacity of an edge between threads.",
            None,
            &edges
                .iter()
                .map(|(name, e)| (label("edge", name), e.capacity as f64))
                .collect::<Vec<_>>(),
        )?;
        Ok(())
    }

    /// The poses by status, the rows lost, the chunk, and the recorder's gauges.
    fn pose_families(&mut self, w: &Watch) -> std::fmt::Result {
        let live = w.live();
        self.counter(
            "mousepose_poses",
            "Poses made, by status (ok, no_mouse, ...).",
            None,
            &PoseStatus::ALL
                .iter()
                .map(|s| (s.name(), 0))
                .chain(live.statuses.iter().map(|(status, n)| (*status, *n)))
                .collect::<BTreeMap<&str, u64>>()
                .into_iter()
                .map(|(status, n)| (label("status", status), n))
                .collect::<Vec<_>>(),
        )?;
        self.counter(
            "mousepose_poses_not_written",
            "Poses that could not be written to poses.csv (full disk, write error).",
            None,
            &[(Vec::new(), live.rows_lost)],
        )?;
        self.gauge(
            "mousepose_chunk",
            "The chunk poses are written to now (0, 1, ...).",
            None,
            &[(Vec::new(), live.chunk as f64)],
        )?;
        if let Some(g) = &w.parts.recorder {
            self.counter(
                "mousepose_recorded",
                "Encoded frame bytes written to the raw recording (it only grows).",
                Some(&Unit::Bytes),
                &[(Vec::new(), g.frame_bytes.load(Ordering::Relaxed))],
            )?;
            let mut lost: BTreeMap<&str, u64> = LOST_AFTER_RECORDING_REASONS.iter().map(|&r| (r, 0)).collect();
            lost.extend(
                g.lost_bytes
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .iter(),
            );
            self.counter(
                "mousepose_lost_after_recording",
                "Encoded frame bytes recorded, then gone from the run's directory (their chunk removed or moved away), by reason.",
                Some(&Unit::Bytes),
                &lost
                    .into_iter()
                    .map(|(reason, n)| (label("reason", reason), n))
                    .collect::<Vec<_>>(),
            )?;
            self.gauge(
                "mousepose_disk_free",
                "Free space on the output's file system.",
                Some(&Unit::Bytes),
                &[(Vec::new(), g.disk_free_bytes.load(Ordering::Relaxed) as f64)],
            )?;
            self.gauge(
                "mousepose_recording_paused",
                "1 while raw recording is paused (disk low or after a write error).",
                None,
                &[(Vec::new(), f64::from(u8::from(g.paused.load(Ordering::Relaxed))))],
            )?;
            self.gauge(
                "mousepose_session_events_waiting",
                "Session events (camera gaps and outages, pauses) waiting for room on the disk.",
                None,
                &[(Vec::new(), g.events_waiting.load(Ordering::Relaxed) as f64)],
            )?;
            self.counter(
                "mousepose_session_events_lost",
                "Session events never written: too many waited for room, or the run ended first.",
                None,
                &[(Vec::new(), g.events_lost.load(Ordering::Relaxed))],
            )?;
        }
        if let Some(stream) = &w.parts.stream {
            self.stream_families(stream.stats())?;
        }
        if let Some(lsl) = &w.parts.lsl {
            self.lsl_families(lsl.stats())?;
        }
        Ok(())
    }

    /// The LSL outlet: whether a reader is connected, samples sent, dropped per reason.
    fn lsl_families(&mut self, stats: &LslStats) -> std::fmt::Result {
        self.gauge(
            "mousepose_lsl_consumers",
            "1 while a reader (LabRecorder, an inlet) is connected to the LSL outlet.",
            None,
            &[(Vec::new(), f64::from(u8::from(stats.has_consumers())))],
        )?;
        self.counter(
            "mousepose_lsl_samples",
            "Samples the LSL outlet handed to liblsl.",
            None,
            &[(Vec::new(), stats.sent())],
        )?;
        self.counter(
            "mousepose_lsl_dropped",
            "Samples of the LSL outlet dropped before liblsl took them, by reason.",
            None,
            &LSL_DROP_REASONS
                .iter()
                .map(|r| (label("reason", r), stats.dropped(r)))
                .collect::<Vec<_>>(),
        )
    }

    /// The live pose stream: subscribers, messages sent per topic, dropped per reason.
    fn stream_families(&mut self, stats: &StreamStats) -> std::fmt::Result {
        self.gauge(
            "mousepose_stream_subscribers",
            "Subscribers connected to the live pose stream.",
            None,
            &[(Vec::new(), stats.subscribers() as f64)],
        )?;
        self.counter(
            "mousepose_stream_messages",
            "Messages the live stream handed to ZeroMQ, by topic.",
            None,
            &Topic::ALL
                .iter()
                .map(|t| (label("topic", t.name()), stats.sent(*t)))
                .collect::<Vec<_>>(),
        )?;
        self.counter(
            "mousepose_stream_dropped",
            "Messages of the live stream dropped before ZeroMQ took them, by reason.",
            None,
            &DROP_REASONS
                .iter()
                .map(|r| (label("reason", r), stats.dropped(r)))
                .collect::<Vec<_>>(),
        )
    }

    /// The process: memory, CPU time, uptime, version.
    fn process_families(&mut self, w: &Watch) -> std::fmt::Result {
        if let Some(bytes) = process_resident_bytes() {
            self.gauge(
                "mousepose_process_resident_memory",
                "Resident memory of the daemon.",
                Some(&Unit::Bytes),
                &[(Vec::new(), bytes as f64)],
            )?;
        }
        self.counter(
            "mousepose_process_cpu",
            "CPU time the daemon used.",
            Some(&Unit::Seconds),
            &[(Vec::new(), process_cpu_s())],
        )?;
        self.gauge(
            "mousepose_run_uptime",
            "Time since the run started.",
            Some(&Unit::Seconds),
            &[(Vec::new(), w.parts.pipeline.elapsed_s())],
        )?;
        self.gauge(
            "mousepose_build_info",
            "The running version (value 1).",
            None,
            &[(label("version", w.parts.info.version), 1.0)],
        )?;
        Ok(())
    }
}
