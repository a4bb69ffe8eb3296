//! The builder of a chain of stages: a [`FlatMap`] at its head, [`Map`] stages one after the
//! other, a [`Sink`] at its end. Each declaration is one call; the builder creates the bounded
//! edge between each stage and the next, names it after both (`segment->body`), starts the
//! threads in the chain's order and checks at compile time that each stage takes what the one
//! before it gives.
//!
//! ```text
//! Chain::head(runner, edge, workers, sync, frames)   "sync"
//!     .map(segment)?                                 "sync->segment"  "segment"
//!     .map_parallel(body)?                           "segment->body"  "body-0" .. "body-N"
//!     .sink("poses", writer, latency)?               "body->poses"    "poses"
//! ```

use super::edge::{EdgeConfig, EdgeSender, EdgeStats, edge};
use super::metrics::Histogram;
use super::runner::Runner;
use super::stage::{FlatMap, Map, Sink, Tracked};
use crossbeam_channel::Receiver;
use std::sync::Arc;

/// An edge the builder made: its name, size and policy, and counters.
pub type NamedEdge = (String, EdgeConfig, Arc<EdgeStats>);

/// Starts the last stage declared once the edge out of it exists.
type Start<T> = Box<dyn FnOnce(&mut Runner, EdgeSender<Tracked<T>>) -> std::io::Result<()>>;

/// A chain being declared, whose last stage gives `T`.
pub struct Chain<'r, T> {
    runner: &'r mut Runner,
    edge: EdgeConfig,
    workers: usize,
    edges: Vec<NamedEdge>,
    /// The name of the last stage declared, and how to start it.
    last: &'static str,
    start: Start<T>,
}

impl<T> std::fmt::Debug for Chain<'_, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Chain")
            .field("edge", &self.edge)
            .field("workers", &self.workers)
            .field("edges", &self.edges)
            .field("last", &self.last)
            .finish_non_exhaustive()
    }
}

impl<'r, T: Send + 'static> Chain<'r, T> {
    /// A chain on `runner` whose edges are all `edge` and whose parallel stages have `workers`
    /// workers each (at least one), starting with `head` reading `input`.
    pub fn head<S: FlatMap<Out = T>>(
        runner: &'r mut Runner,
        edge: EdgeConfig,
        workers: usize,
        head: S,
        input: Receiver<S::In>,
    ) -> Self {
        Self {
            runner,
            edge,
            workers: workers.max(1),
            edges: Vec::new(),
            last: S::NAME,
            start: Box::new(move |runner, output| runner.flat_map(head, input, output)),
        }
    }

    /// The edge from the last stage to `to`: starts the last stage on it and hands back its
    /// receiving end.
    fn link(&mut self, to: &str) -> std::io::Result<Receiver<Tracked<T>>> {
        let (tx, rx, stats) = edge(self.edge);
        self.edges.push((format!("{}->{to}", self.last), self.edge, stats));
        let start = std::mem::replace(&mut self.start, Box::new(|_, _| Ok(())));
        start(self.runner, tx)?;
        Ok(rx)
    }

    /// The chain whose last stage is now `last`, which `start` starts.
    fn then<U: Send + 'static>(self, last: &'static str, start: Start<U>) -> Chain<'r, U> {
        Chain {
            runner: self.runner,
            edge: self.edge,
            workers: self.workers,
            edges: self.edges,
            last,
            start,
        }
    }

    /// Adds `stage` on one thread that sees its items in index order: for a stage that carries
    /// state from one frame to the next, so that its output does not depend on thread timing.
    ///
    /// # Errors
    /// The previous stage's threads cannot be created.
    pub fn map<S: Map<In = T>>(mut self, stage: S) -> std::io::Result<Chain<'r, S::Out>> {
        let input = self.link(S::NAME)?;
        Ok(self.then(
            S::NAME,
            Box::new(move |runner, output| runner.map_in_order(stage, &input, &output).map(drop)),
        ))
    }

    /// Adds `stage` on the chain's number of workers (copies of it), which take the items as
    /// they come: for a stage without memory from frame to frame.
    ///
    /// # Errors
    /// The previous stage's threads cannot be created.
    pub fn map_parallel<S: Map<In = T> + Clone>(mut self, stage: S) -> std::io::Result<Chain<'r, S::Out>> {
        let input = self.link(S::NAME)?;
        let workers = vec![stage; self.workers];
        Ok(self.then(
            S::NAME,
            Box::new(move |runner, output| runner.map(workers, &input, &output).map(drop)),
        ))
    }

    /// Ends the chain with `sink`, which writes the items in index order; `end_to_end` gets
    /// each item's time from entering the pipeline to written. Starts every thread not started
    /// yet and returns the chain's edges.
    ///
    /// # Errors
    /// A thread cannot be created.
    pub fn sink<K: Sink<In = T>>(
        mut self,
        name: &'static str,
        sink: K,
        end_to_end: Arc<Histogram>,
    ) -> std::io::Result<Vec<NamedEdge>> {
        let input = self.link(name)?;
        self.runner.sink(name, sink, input, end_to_end)?;
        Ok(self.edges)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::pipeline::{StageError, reports_of};
    use std::sync::Mutex;

    /// Pairs up numbers: emits one item for every second input, and the odd one out at the end.
    struct Pairs(Option<u32>);

    impl FlatMap for Pairs {
        type In = u32;
        type Out = (u32, u32);
        const NAME: &'static str = "pairs";
        fn process(&mut self, input: u32, out: &mut Vec<(u32, u32)>) -> Result<(), StageError> {
            match self.0.take() {
                Some(first) => out.push((first, input)),
                None => self.0 = Some(input),
            }
            Ok(())
        }
        fn finish(&mut self, out: &mut Vec<(u32, u32)>) -> Result<(), StageError> {
            out.extend(self.0.take().map(|a| (a, a)));
            Ok(())
        }
    }

    #[derive(Clone)]
    struct Sum;

    impl Map for Sum {
        type In = (u32, u32);
        type Out = u32;
        const NAME: &'static str = "sum";
        fn process(&mut self, (a, b): (u32, u32)) -> Result<u32, StageError> {
            Ok(a + b)
        }
    }

    /// Numbers what it sees: its output depends on the order of its input.
    struct Count(u32);

    impl Map for Count {
        type In = u32;
        type Out = (u32, u32);
        const NAME: &'static str = "count";
        fn process(&mut self, input: u32) -> Result<(u32, u32), StageError> {
            self.0 += 1;
            Ok((self.0, input))
        }
    }

    #[derive(Debug)]
    struct Collect(Arc<Mutex<Vec<(u32, u32)>>>);

    impl Sink for Collect {
        type In = (u32, u32);
        fn write(&mut self, item: (u32, u32)) -> Result<(), StageError> {
            self.0.lock().map_err(|_| "poisoned")?.push(item);
            Ok(())
        }
        fn flush(&mut self) -> Result<(), StageError> {
            Ok(())
        }
    }

    #[test]
    fn a_declared_chain_names_its_edges_and_threads_after_its_stages_and_keeps_every_item_in_order() {
        let (tx, rx) = crossbeam_channel::bounded(4);
        let got = Arc::new(Mutex::new(Vec::new()));
        let mut runner = Runner::new();
        runner
            .spawn("source", move || {
                for i in 0..401u32 {
                    tx.send(i)?;
                }
                Ok(())
            })
            .unwrap();
        let edges = Chain::head(&mut runner, EdgeConfig::block(2), 3, Pairs(None), rx)
            .map_parallel(Sum)
            .unwrap()
            .map(Count(0))
            .unwrap()
            .sink("collect", Collect(Arc::clone(&got)), Arc::default())
            .unwrap();
        let names: Vec<&str> = edges.iter().map(|(name, _, _)| name.as_str()).collect();
        assert_eq!(names, ["pairs->sum", "sum->count", "count->collect"]);
        assert!(edges.iter().all(|(_, config, _)| *config == EdgeConfig::block(2)));
        let threads = runner.thread_names();
        assert_eq!(
            threads,
            ["source", "pairs", "sum-0", "sum-1", "sum-2", "count", "collect"]
        );
        let stages: Vec<(String, u64, u64)> = reports_of(&runner.stage_stats())
            .into_iter()
            .map(|r| (r.name, r.items_in, r.items_out))
            .collect();
        runner.join().unwrap();
        // 401 numbers make 200 pairs and the odd one out; the sums arrive from three workers
        // in any order, and `count` numbers them in the pairs' order.
        let expected: Vec<(u32, u32)> = (0..200u32).map(|k| (k + 1, 4 * k + 1)).chain([(201, 800)]).collect();
        assert_eq!(*got.lock().unwrap(), expected);
        // The reports read before the join may be partial; the names and their order are not.
        let names: Vec<&str> = stages.iter().map(|(name, _, _)| name.as_str()).collect();
        assert_eq!(names, ["sum", "count", "collect"]);
        assert!(stages.iter().all(|(_, items_in, items_out)| items_out <= items_in));
        let per_edge: Vec<u64> = edges
            .iter()
            .map(|(_, _, stats)| stats.sent.load(std::sync::atomic::Ordering::Relaxed))
            .collect();
        assert_eq!(per_edge, [201, 201, 201]);
    }
}
