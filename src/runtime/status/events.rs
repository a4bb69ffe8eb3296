//! The last events of the process (outages, chunk rotations, disk warnings: whatever it logs at
//! `info` and above), kept in memory for the live page. A `tracing` layer feeds it, so every
//! event that reaches the log reaches the page too, from one place.

use serde::Serialize;
use std::collections::VecDeque;
use std::fmt::Write as _;
use std::sync::{Arc, Mutex, OnceLock, PoisonError};
use tracing::field::{Field, Visit};

/// Events kept.
const CAPACITY: usize = 200;

/// One logged event.
#[derive(Clone, Debug, Serialize, PartialEq, Eq)]
pub struct Event {
    /// Numbered from 1 in the order logged, so a reader can ask for what is new.
    pub id: u64,
    /// RFC 3339 UTC.
    pub time_utc: String,
    /// `INFO`, `WARN` or `ERROR`.
    pub level: &'static str,
    /// The message and its fields (`key=value`).
    pub text: String,
}

/// The last [`CAPACITY`] events.
#[derive(Debug, Default)]
pub struct EventLog {
    events: Mutex<(u64, VecDeque<Event>)>,
}

impl EventLog {
    /// The process's log (the one the logging layer feeds).
    pub fn global() -> Arc<EventLog> {
        static LOG: OnceLock<Arc<EventLog>> = OnceLock::new();
        Arc::clone(LOG.get_or_init(Arc::default))
    }

    pub fn push(&self, level: &'static str, text: String) {
        let mut guard = self.events.lock().unwrap_or_else(PoisonError::into_inner);
        let (next, events) = &mut *guard;
        *next += 1;
        if events.len() == CAPACITY {
            events.pop_front();
        }
        events.push_back(Event {
            id: *next,
            time_utc: crate::runtime::capture::clock::utc_now(),
            level,
            text,
        });
    }

    /// The events kept, oldest first.
    pub fn recent(&self) -> Vec<Event> {
        let guard = self.events.lock().unwrap_or_else(PoisonError::into_inner);
        guard.1.iter().cloned().collect()
    }
}

/// The `tracing` layer that feeds [`EventLog::global`] with events at `info` and above.
#[derive(Debug)]
pub struct EventLayer(pub Arc<EventLog>);

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for EventLayer {
    fn on_event(&self, event: &tracing::Event<'_>, _ctx: tracing_subscriber::layer::Context<'_, S>) {
        let level = match *event.metadata().level() {
            tracing::Level::ERROR => "ERROR",
            tracing::Level::WARN => "WARN",
            tracing::Level::INFO => "INFO",
            _ => return,
        };
        let mut text = Text::default();
        event.record(&mut text);
        self.0.push(level, text.0);
    }
}

/// An event's message followed by its fields.
#[derive(Default)]
struct Text(String);

impl Visit for Text {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let fields = std::mem::take(&mut self.0);
            let _ = write!(self.0, "{value:?}");
            self.0.push_str(&fields);
        } else {
            let _ = write!(self.0, " {}={value:?}", field.name());
        }
    }

    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0.insert_str(0, value);
        } else {
            let _ = write!(self.0, " {}={value}", field.name());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tracing_subscriber::layer::SubscriberExt as _;

    #[test]
    fn events_at_info_and_above_are_kept_with_their_fields_and_old_ones_go() {
        let log = Arc::new(EventLog::default());
        let subscriber = tracing_subscriber::registry().with(EventLayer(Arc::clone(&log)));
        tracing::subscriber::with_default(subscriber, || {
            tracing::debug!("not kept");
            tracing::warn!(chunk = 3, "disk space low");
            for i in 0..CAPACITY {
                tracing::info!(i, "filler");
            }
        });
        let events = log.recent();
        assert_eq!(events.len(), CAPACITY);
        // The warning was the first of CAPACITY + 1 kept events: it went, the filler stayed.
        assert_eq!(events[0].id, 2);
        assert_eq!(events[0].text, "filler i=0");
        assert_eq!(events[0].level, "INFO");
        let log = Arc::new(EventLog::default());
        let subscriber = tracing_subscriber::registry().with(EventLayer(Arc::clone(&log)));
        tracing::subscriber::with_default(subscriber, || tracing::warn!(chunk = 3, "disk space low"));
        let events = log.recent();
        assert_eq!(
            (events[0].level, events[0].text.as_str()),
            ("WARN", "disk space low chunk=3")
        );
    }
}
