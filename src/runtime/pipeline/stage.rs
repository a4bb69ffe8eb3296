//! What a step of the pipeline is: a [`Map`] (one output per input, which its signature
//! guarantees), a [`FlatMap`] (any number of outputs per input: the synchroniser) or a
//! [`Sink`] (the end). Each declares the type it takes and the type it gives, and a `Map` or
//! `FlatMap` its name; [`super::Chain`] joins them with named edges.
//!
//! Steps are plain objects: they never see a channel, a thread or a clock, so a unit test calls
//! `process` directly.

use std::time::Instant;

/// Why a stage, sink or source failed: the component's own error, kept as the cause.
pub type StageError = Box<dyn std::error::Error + Send + Sync>;

/// A processing step that turns each input into exactly one output (a frame without a result
/// is an output with a status). The one-to-one contract is the signature: a `Map` can neither
/// drop nor duplicate an item, so every frame stays accounted for and the sink can restore the
/// order behind a stage with several workers.
pub trait Map: Send + 'static {
    type In: Send + 'static;
    type Out: Send + 'static;
    /// The stage's thread name (`NAME-0`, `NAME-1`, ... with several workers) and its side of
    /// the names of the edges into and out of it (`sync->segment`).
    const NAME: &'static str;
    /// # Errors
    /// A failure that must stop the run (a bad frame is an output with a status, not an error).
    fn process(&mut self, input: Self::In) -> Result<Self::Out, StageError>;
}

/// A step that may drop, merge or multiply items: frames of two cameras in, pairs out. It runs
/// on one thread and the runner numbers what it emits (from 0, without gaps), so a `FlatMap`
/// starts the chain of [`Map`] stages behind it.
pub trait FlatMap: Send + 'static {
    type In: Send + 'static;
    type Out: Send + 'static;
    /// The step's thread name and its side of the name of the edge out of it.
    const NAME: &'static str;
    /// Pushes the outputs (zero or more) that `input` completes.
    ///
    /// # Errors
    /// A failure that must stop the run.
    fn process(&mut self, input: Self::In, out: &mut Vec<Self::Out>) -> Result<(), StageError>;
    /// At the end of the input: pushes what is still held.
    ///
    /// # Errors
    /// A failure that must stop the run.
    fn finish(&mut self, out: &mut Vec<Self::Out>) -> Result<(), StageError> {
        let _ = out;
        Ok(())
    }
    /// When (host clock, `CLOCK_MONOTONIC` ns) the step wants [`FlatMap::tick`] called if no
    /// input came before; `None`: only on input.
    fn due_ns(&self) -> Option<u64> {
        None
    }
    /// Pushes the outputs that the time `now_ns` (host clock) completes, without input.
    ///
    /// # Errors
    /// A failure that must stop the run.
    fn tick(&mut self, now_ns: u64, out: &mut Vec<Self::Out>) -> Result<(), StageError> {
        let _ = (now_ns, out);
        Ok(())
    }
}

/// The end of the pipeline: writes what reaches it.
pub trait Sink: Send + std::fmt::Debug + 'static {
    type In: Send + 'static;
    /// # Errors
    /// The item cannot be written.
    fn write(&mut self, item: Self::In) -> Result<(), StageError>;
    /// # Errors
    /// What was written cannot be made durable.
    fn flush(&mut self) -> Result<(), StageError>;
}

/// A sink chosen at run time (one file, or chunk after chunk).
impl<K: Sink + ?Sized> Sink for Box<K> {
    type In = K::In;
    fn write(&mut self, item: Self::In) -> Result<(), StageError> {
        (**self).write(item)
    }
    fn flush(&mut self) -> Result<(), StageError> {
        (**self).flush()
    }
}

/// An item with its place in the run and the instant it entered the pipeline.
#[derive(Debug)]
pub struct Tracked<T> {
    pub index: u64,
    pub entered: Instant,
    pub item: T,
}

impl<T> Tracked<T> {
    pub fn new(index: u64, item: T) -> Self {
        Self {
            index,
            entered: Instant::now(),
            item,
        }
    }
}
