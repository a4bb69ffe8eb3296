//! The runner: starts one named thread per source, stage worker and sink, joins them in
//! order, and reports which one failed.
//!
//! Stages and sinks are plain objects ([`Map`], [`FlatMap`], [`Sink`]); the runner owns the
//! channels, the timing and the counters. Items travel wrapped in [`Tracked`], which carries
//! the pair's index and the instant it entered the pipeline, so the sink can measure end-to-end
//! latency and restore order behind a stage with several workers. [`super::Chain`] declares a
//! chain of stages on a runner.

use super::edge::{EdgeSender, Sent};
use super::metrics::{Histogram, LatencySummary};
use super::stage::{FlatMap, Map, Sink, StageError, Tracked};
use crate::runtime::capture::clock::monotonic_ns;
use crossbeam_channel::{Receiver, RecvTimeoutError};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Instant;

/// Counters of one stage (all its workers) or sink.
#[derive(Debug, Default)]
pub struct StageStats {
    pub items_in: AtomicU64,
    pub items_out: AtomicU64,
    /// Time spent in `process` or `write` per item.
    pub latency: Histogram,
}

/// What a stage did, for summaries.
#[derive(Clone, Debug, Serialize)]
pub struct StageReport {
    pub name: String,
    pub items_in: u64,
    pub items_out: u64,
    pub latency: LatencySummary,
}

/// A component that stopped the run.
#[derive(Debug, thiserror::Error)]
#[error("{name} failed")]
pub struct PipelineError {
    pub name: String,
    #[source]
    pub source: StageError,
}

/// The stop signal sources check between frames.
#[derive(Clone, Debug, Default)]
pub struct Shutdown(Arc<AtomicBool>);

impl Shutdown {
    pub fn request(&self) {
        self.0.store(true, Ordering::Release);
    }

    pub fn requested(&self) -> bool {
        self.0.load(Ordering::Acquire)
    }

    /// The flag itself, for a signal handler to set.
    pub fn flag(&self) -> Arc<AtomicBool> {
        Arc::clone(&self.0)
    }
}

/// The threads of a running pipeline.
#[derive(Debug, Default)]
pub struct Runner {
    threads: Vec<(String, JoinHandle<Result<(), StageError>>)>,
    stages: Vec<(String, Arc<StageStats>)>,
    shutdown: Shutdown,
    /// Set when any thread fails: stages and sinks stop at their next item.
    failed: Shutdown,
}

impl Runner {
    pub fn new() -> Self {
        Self::default()
    }

    /// The signal that stops the sources.
    pub fn shutdown(&self) -> Shutdown {
        self.shutdown.clone()
    }

    /// Starts a thread named `name` running `body`. Start threads in topological order
    /// (sources first): [`Runner::join`] joins them in that order.
    ///
    /// # Errors
    /// The thread cannot be created.
    pub fn spawn(
        &mut self,
        name: &str,
        body: impl FnOnce() -> Result<(), StageError> + Send + 'static,
    ) -> std::io::Result<()> {
        let (shutdown, failed) = (self.shutdown.clone(), self.failed.clone());
        let handle = std::thread::Builder::new().name(name.to_owned()).spawn(move || {
            // A panic is a failure like any other: it stops the whole run, which is then
            // reported failed, instead of leaving the other workers going on without it.
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(body))
                .unwrap_or_else(|panic| Err(format!("panicked: {}", panic_message(panic.as_ref())).into()));
            if result.is_err() {
                failed.request();
                shutdown.request();
            }
            result
        })?;
        self.threads.push((name.to_owned(), handle));
        Ok(())
    }

    /// Starts a stage with one thread per worker (`NAME-0`, `NAME-1`, ... when several), all
    /// reading `input` and sending to `output`, each taking the items as they come.
    ///
    /// # Errors
    /// A thread cannot be created.
    pub fn map<S: Map>(
        &mut self,
        workers: Vec<S>,
        input: &Receiver<Tracked<S::In>>,
        output: &EdgeSender<Tracked<S::Out>>,
    ) -> std::io::Result<Arc<StageStats>> {
        self.start_map(workers, input, output, false)
    }

    /// Starts a stage with one worker that sees its items in index order (items that arrive
    /// early from a stage with several workers wait): for stages that carry state from one
    /// frame to the next, so that their output does not depend on thread timing.
    ///
    /// # Errors
    /// The thread cannot be created.
    pub fn map_in_order<S: Map>(
        &mut self,
        stage: S,
        input: &Receiver<Tracked<S::In>>,
        output: &EdgeSender<Tracked<S::Out>>,
    ) -> std::io::Result<Arc<StageStats>> {
        self.start_map(vec![stage], input, output, true)
    }

    fn start_map<S: Map>(
        &mut self,
        workers: Vec<S>,
        input: &Receiver<Tracked<S::In>>,
        output: &EdgeSender<Tracked<S::Out>>,
        in_order: bool,
    ) -> std::io::Result<Arc<StageStats>> {
        let stats = Arc::new(StageStats::default());
        let several = workers.len() > 1;
        for (k, mut stage) in workers.into_iter().enumerate() {
            let thread = if several {
                format!("{}-{k}", S::NAME)
            } else {
                S::NAME.to_owned()
            };
            let (rx, tx, stats) = (input.clone(), output.clone(), Arc::clone(&stats));
            let failed = self.failed.clone();
            self.spawn(&thread, move || {
                let mut order = Reorder::default();
                let mut ready = Vec::new();
                for tracked in rx.iter() {
                    if failed.requested() {
                        // Another component failed and says so: stop quietly.
                        return Ok(());
                    }
                    stats.items_in.fetch_add(1, Ordering::Relaxed);
                    if in_order {
                        order.push(tracked, &mut ready)?;
                    } else {
                        ready.push(tracked);
                    }
                    for Tracked { index, entered, item } in ready.drain(..) {
                        let start = Instant::now();
                        let item = stage.process(item)?;
                        stats.latency.record(start.elapsed());
                        stats.items_out.fetch_add(1, Ordering::Relaxed);
                        if tx.send(Tracked { index, entered, item }) == Sent::Closed {
                            // Downstream stopped (it failed and says so): stop quietly.
                            return Ok(());
                        }
                    }
                }
                order.finish()
            })?;
        }
        self.stages.push((S::NAME.to_owned(), Arc::clone(&stats)));
        Ok(stats)
    }

    /// Starts a [`FlatMap`] on one thread named after it, reading `input` and sending what it
    /// emits to `output`, numbered from 0 and marked as entering the pipeline there; when no
    /// input comes by the time it asks for ([`FlatMap::due_ns`]), its `tick` is called. Its work
    /// is not a stage's in the reports: the synchroniser's shows in the frames' accounting
    /// (paired, unpaired, rejected).
    ///
    /// # Errors
    /// The thread cannot be created.
    pub fn flat_map<S: FlatMap>(
        &mut self,
        mut stage: S,
        input: Receiver<S::In>,
        output: EdgeSender<Tracked<S::Out>>,
    ) -> std::io::Result<()> {
        self.spawn(S::NAME, move || {
            let mut out = Vec::new();
            let mut index = 0u64;
            let mut send = |out: &mut Vec<S::Out>| -> bool {
                for item in out.drain(..) {
                    if output.send(Tracked::new(index, item)) == Sent::Closed {
                        return false;
                    }
                    index += 1;
                }
                true
            };
            loop {
                let item = match stage.due_ns() {
                    None => match input.recv() {
                        Ok(item) => item,
                        Err(_) => break,
                    },
                    Some(due) => {
                        let wait = due.saturating_sub(monotonic_ns());
                        match input.recv_timeout(std::time::Duration::from_nanos(wait)) {
                            Ok(item) => item,
                            Err(RecvTimeoutError::Timeout) => {
                                stage.tick(monotonic_ns(), &mut out)?;
                                if !send(&mut out) {
                                    return Ok(());
                                }
                                continue;
                            }
                            Err(RecvTimeoutError::Disconnected) => break,
                        }
                    }
                };
                stage.process(item, &mut out)?;
                if !send(&mut out) {
                    // Downstream stopped (it failed and says so): stop quietly.
                    return Ok(());
                }
            }
            stage.finish(&mut out)?;
            send(&mut out);
            Ok(())
        })
    }

    /// Starts a sink thread. Items are written in index order (indices start at 0 and have no
    /// gaps: a [`Map`] emits one output per input; items from workers that ran ahead wait);
    /// `end_to_end` gets each item's time from entering the pipeline to written.
    ///
    /// # Errors
    /// The thread cannot be created.
    pub fn sink<K: Sink>(
        &mut self,
        name: &str,
        mut sink: K,
        input: Receiver<Tracked<K::In>>,
        end_to_end: Arc<Histogram>,
    ) -> std::io::Result<Arc<StageStats>> {
        let stats = Arc::new(StageStats::default());
        let st = Arc::clone(&stats);
        let failed = self.failed.clone();
        self.spawn(name, move || {
            let mut order = Reorder::default();
            let mut ready = Vec::new();
            let write = |t: Tracked<K::In>, sink: &mut K| -> Result<(), StageError> {
                let start = Instant::now();
                sink.write(t.item)?;
                st.latency.record(start.elapsed());
                end_to_end.record(t.entered.elapsed());
                st.items_out.fetch_add(1, Ordering::Relaxed);
                Ok(())
            };
            for t in input.iter() {
                if failed.requested() {
                    return Ok(());
                }
                st.items_in.fetch_add(1, Ordering::Relaxed);
                order.push(t, &mut ready)?;
                for t in ready.drain(..) {
                    write(t, &mut sink)?;
                }
            }
            order.finish()?;
            sink.flush()
        })?;
        self.stages.push((name.to_owned(), Arc::clone(&stats)));
        Ok(stats)
    }

    /// The names of the threads started so far, in start order.
    pub fn thread_names(&self) -> Vec<&str> {
        self.threads.iter().map(|(name, _)| name.as_str()).collect()
    }

    /// Per stage and sink, its live counters.
    pub fn stage_stats(&self) -> Vec<(String, Arc<StageStats>)> {
        self.stages.clone()
    }

    /// Per stage and sink: items in and out, time per item.
    pub fn reports(&self) -> Vec<StageReport> {
        reports_of(&self.stages)
    }

    /// Waits for every thread in start order and returns the stage reports.
    ///
    /// # Errors
    /// The first component (in start order) that failed or panicked.
    pub fn join(self) -> Result<Vec<StageReport>, PipelineError> {
        let Runner { threads, stages, .. } = self;
        let mut first: Option<PipelineError> = None;
        for (name, handle) in threads {
            let result = handle
                .join()
                .unwrap_or_else(|panic| Err(format!("panicked: {}", panic_message(panic.as_ref())).into()));
            if let (Err(source), None) = (result, &first) {
                first = Some(PipelineError { name, source });
            }
        }
        match first {
            Some(e) => Err(e),
            None => Ok(reports_of(&stages)),
        }
    }
}

/// What a panic carried, as text.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| (*s).to_owned())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".to_owned())
}

/// Items a reorder buffer holds at most while it waits for a late one. Every edge before it is
/// bounded, so only a worker stuck on one item lets later items pile up here: past this many,
/// the run fails (and a daemon is restarted) instead of growing without limit.
pub const REORDER_LIMIT: usize = 1024;

/// Puts items back in index order (indices start at 0 and have no gaps).
#[derive(Debug)]
struct Reorder<T> {
    held: BTreeMap<u64, Tracked<T>>,
    next: u64,
    limit: usize,
}

impl<T> Default for Reorder<T> {
    fn default() -> Self {
        Self {
            held: BTreeMap::new(),
            next: 0,
            limit: REORDER_LIMIT,
        }
    }
}

impl<T> Reorder<T> {
    /// Takes an item and appends those now due to `due`, in order.
    ///
    /// # Errors
    /// More than the limit of items wait for one that has not come.
    fn push(&mut self, t: Tracked<T>, due: &mut Vec<Tracked<T>>) -> Result<(), StageError> {
        self.held.insert(t.index, t);
        while let Some(t) = self.held.remove(&self.next) {
            self.next += 1;
            due.push(t);
        }
        if self.held.len() > self.limit {
            return Err(format!(
                "item {} has not come after {} later ones: a worker is stuck",
                self.next,
                self.held.len()
            )
            .into());
        }
        Ok(())
    }

    /// At the end of the input: an error when an item never arrived.
    fn finish(&self) -> Result<(), StageError> {
        match self.held.keys().next() {
            Some(&index) => Err(format!("item {} never arrived (item {index} did)", self.next).into()),
            None => Ok(()),
        }
    }
}

/// Per stage and sink: items in and out, time per item.
pub fn reports_of(stages: &[(String, Arc<StageStats>)]) -> Vec<StageReport> {
    stages
        .iter()
        .map(|(name, s)| StageReport {
            name: name.clone(),
            items_in: s.items_in.load(Ordering::Relaxed),
            items_out: s.items_out.load(Ordering::Relaxed),
            latency: s.latency.summary(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::pipeline::{EdgeConfig, edge};

    /// Doubles its input; fails on `fail_on`.
    struct Double {
        fail_on: Option<u32>,
    }

    impl Map for Double {
        type In = u32;
        type Out = u32;
        const NAME: &'static str = "double";
        fn process(&mut self, input: u32) -> Result<u32, StageError> {
            if Some(input) == self.fail_on {
                return Err(format!("cannot double {input}").into());
            }
            Ok(input * 2)
        }
    }

    #[derive(Debug)]
    struct Collect(Arc<std::sync::Mutex<Vec<u32>>>);

    impl Sink for Collect {
        type In = u32;
        fn write(&mut self, item: u32) -> Result<(), StageError> {
            self.0.lock().map_err(|_| "poisoned")?.push(item);
            Ok(())
        }
        fn flush(&mut self) -> Result<(), StageError> {
            Ok(())
        }
    }

    fn run(n: u32, workers: usize, fail_on: Option<u32>) -> (Result<Vec<StageReport>, PipelineError>, Vec<u32>) {
        let (src_tx, src_rx, _) = edge(EdgeConfig::block(4));
        let (out_tx, out_rx, _) = edge(EdgeConfig::block(4));
        let got = Arc::new(std::sync::Mutex::new(Vec::new()));
        let mut runner = Runner::new();
        runner
            .spawn("source", move || {
                for i in 0..n {
                    if src_tx.send(Tracked::new(u64::from(i), i)) == Sent::Closed {
                        break;
                    }
                }
                Ok(())
            })
            .unwrap();
        let stages = (0..workers).map(|_| Double { fail_on }).collect();
        runner.map(stages, &src_rx, &out_tx).unwrap();
        drop((src_rx, out_tx));
        runner
            .sink("collect", Collect(Arc::clone(&got)), out_rx, Arc::default())
            .unwrap();
        let result = runner.join();
        let got = got.lock().unwrap().clone();
        (result, got)
    }

    #[test]
    fn several_workers_keep_the_order_and_every_item() {
        let (result, got) = run(500, 3, None);
        let reports = result.unwrap();
        assert_eq!(got, (0..500).map(|i| i * 2).collect::<Vec<_>>());
        let double = reports.iter().find(|r| r.name == "double").unwrap();
        assert_eq!((double.items_in, double.items_out), (500, 500));
        assert_eq!(double.latency.count, 500);
    }

    /// Passes its input on and remembers the order it saw it in.
    struct Witness(Arc<std::sync::Mutex<Vec<u32>>>);

    impl Map for Witness {
        type In = u32;
        type Out = u32;
        const NAME: &'static str = "witness";
        fn process(&mut self, input: u32) -> Result<u32, StageError> {
            self.0.lock().map_err(|_| "poisoned")?.push(input);
            Ok(input)
        }
    }

    #[test]
    fn an_in_order_stage_sees_items_in_order_behind_several_workers() {
        let (src_tx, src_rx, _) = edge(EdgeConfig::block(4));
        let (mid_tx, mid_rx, _) = edge(EdgeConfig::block(4));
        let (out_tx, out_rx, _) = edge(EdgeConfig::block(4));
        let seen = Arc::new(std::sync::Mutex::new(Vec::new()));
        let mut runner = Runner::new();
        runner
            .spawn("source", move || {
                // Fewer items than the reorder bound: a worker descheduled on a busy machine while
                // the others run ahead must not look stuck.
                for i in 0..1_000u32 {
                    src_tx.send(Tracked::new(u64::from(i), i));
                }
                Ok(())
            })
            .unwrap();
        let workers = (0..3).map(|_| Double { fail_on: None }).collect();
        runner.map(workers, &src_rx, &mid_tx).unwrap();
        runner
            .map_in_order(Witness(Arc::clone(&seen)), &mid_rx, &out_tx)
            .unwrap();
        drop((src_rx, mid_tx, mid_rx, out_tx));
        runner
            .sink("collect", Collect(Arc::default()), out_rx, Arc::default())
            .unwrap();
        runner.join().unwrap();
        assert_eq!(*seen.lock().unwrap(), (0..1_000).map(|i| i * 2).collect::<Vec<_>>());
    }

    #[test]
    fn a_failing_stage_stops_the_run_and_is_named() {
        let (result, got) = run(10_000, 2, Some(100));
        let e = result.unwrap_err();
        assert!(e.name.starts_with("double"), "{}", e.name);
        assert!(e.source.to_string().contains("cannot double 100"));
        assert!(got.len() < 1_000, "{} items written after the failure", got.len());
    }

    /// Doubles its input and panics on one.
    struct PanicsOn(u32);

    impl Map for PanicsOn {
        type In = u32;
        type Out = u32;
        const NAME: &'static str = "double";
        fn process(&mut self, input: u32) -> Result<u32, StageError> {
            assert_ne!(input, self.0, "a bug in a stage");
            Ok(input * 2)
        }
    }

    #[test]
    fn a_panicking_worker_fails_the_run_instead_of_leaving_the_others_going() {
        let (src_tx, src_rx, _) = edge(EdgeConfig::block(4));
        let (out_tx, out_rx, _) = edge(EdgeConfig::block(4));
        let got = Arc::new(std::sync::Mutex::new(Vec::new()));
        let mut runner = Runner::new();
        let shutdown = runner.shutdown();
        let stopped = Arc::new(AtomicBool::new(false));
        let seen = Arc::clone(&stopped);
        runner
            .spawn("source", move || {
                for i in 0..100u32 {
                    if src_tx.send(Tracked::new(u64::from(i), i)) == Sent::Closed {
                        break;
                    }
                }
                // Nothing else fails: only the panic itself can ask the source to stop.
                let deadline = Instant::now() + std::time::Duration::from_secs(10);
                while !shutdown.requested() && Instant::now() < deadline {
                    std::thread::sleep(std::time::Duration::from_millis(10));
                }
                seen.store(shutdown.requested(), Ordering::Relaxed);
                Ok(())
            })
            .unwrap();
        runner.map(vec![PanicsOn(50), PanicsOn(50)], &src_rx, &out_tx).unwrap();
        drop((src_rx, out_tx));
        runner
            .sink("collect", Collect(Arc::clone(&got)), out_rx, Arc::default())
            .unwrap();
        let e = runner.join().unwrap_err();
        assert!(e.name.starts_with("double"), "{}", e.name);
        assert!(e.source.to_string().contains("a bug in a stage"), "{}", e.source);
        assert!(got.lock().unwrap().len() < 1_000);
        assert!(stopped.load(Ordering::Relaxed), "the panic did not stop the source");
    }

    #[test]
    fn a_reorder_buffer_waiting_on_a_stuck_item_fails_instead_of_growing() {
        let mut order = Reorder::default();
        let mut due = Vec::new();
        for i in 1..=REORDER_LIMIT as u64 {
            order.push(Tracked::new(i, ()), &mut due).unwrap();
        }
        assert!(due.is_empty());
        let e = order
            .push(Tracked::new(REORDER_LIMIT as u64 + 1, ()), &mut due)
            .unwrap_err();
        assert!(e.to_string().contains("item 0 has not come"), "{e}");
    }
}
