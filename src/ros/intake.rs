//! What the node says about the messages it takes, built so that nothing
//! the loop must do (step, publish, answer services) waits on it:
//!
//! - [`Log`]: the node's lines go to stderr and to `/rosout` through a
//!   bounded queue each, written by a thread of their own. The loop never
//!   writes itself: a stderr that nobody reads (a full pipe) or a slow
//!   `/rosout` holds only its writer thread; lines that find the queue full
//!   are counted and the writer says how many it lost when it can write
//!   again.
//! - [`TopicLog`]: per topic, what the messages did (applied, refused,
//!   undecodable) is logged one by one for the first [`LOG_FIRST`] messages
//!   of each [`LOG_WINDOW`], then held and summed up in one line at the end
//!   of the window. The counts in `diagnostics` stay exact; the log stays
//!   a few lines a second whatever arrives.

use std::io::Write as _;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Lines a topic logs one by one in each window before it holds them.
pub const LOG_FIRST: u32 = 5;
/// The window of [`LOG_FIRST`] and of the summaries.
pub const LOG_WINDOW: Duration = Duration::from_secs(1);
/// Lines waiting for each writer thread; more are counted and lost.
pub const LOG_QUEUE: usize = 256;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    Info,
    Warn,
}

type Line = (Level, String);

/// One writer thread and its queue.
struct Lane {
    tx: Option<SyncSender<Line>>,
    lost: Arc<AtomicU64>,
    /// Closed by the thread when it has written everything.
    done: Receiver<()>,
}

impl Lane {
    fn spawn(name: &str, mut write: impl FnMut(Level, &str) + Send + 'static) -> Lane {
        let (tx, rx) = mpsc::sync_channel::<Line>(LOG_QUEUE);
        let (done_tx, done) = mpsc::channel();
        let lost = Arc::new(AtomicU64::new(0));
        let counted = lost.clone();
        let note_lost = move |write: &mut dyn FnMut(Level, &str)| {
            let n = counted.swap(0, Ordering::Relaxed);
            if n > 0 {
                write(
                    Level::Warn,
                    &format!(
                        "{n} log lines not written: they came faster than this log \
                         (stderr or /rosout) took them"
                    ),
                );
            }
        };
        let spawned = std::thread::Builder::new()
            .name(name.into())
            .spawn(move || {
                for (level, text) in rx {
                    note_lost(&mut write);
                    write(level, &text);
                }
                note_lost(&mut write);
                drop(done_tx);
            });
        Lane {
            // without its thread, lines are counted as lost
            tx: spawned.is_ok().then_some(tx),
            lost,
            done,
        }
    }

    fn send(&self, line: Line) {
        match self.tx.as_ref().map(|tx| tx.try_send(line)) {
            Some(Ok(())) => {}
            Some(Err(TrySendError::Disconnected(_))) | None | Some(Err(TrySendError::Full(_))) => {
                self.lost.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// The node's log: stderr and, given a handle, `/rosout`; see the module.
pub struct Log {
    lanes: Vec<Lane>,
}

impl Log {
    /// A log to stderr (lines prefixed `[garment_sim] `) and to `/rosout`
    /// through `rosout` if given.
    pub fn new(rosout: Option<ros2_client::NodeLoggingHandle>) -> Log {
        let mut lanes = vec![Lane::spawn("log-stderr", |level, text| {
            let warn = if level == Level::Warn {
                "warning: "
            } else {
                ""
            };
            // a closed stderr is not an error of the node
            let _ = writeln!(std::io::stderr().lock(), "[garment_sim] {warn}{text}");
        })];
        if let Some(handle) = rosout {
            lanes.push(Lane::spawn("log-rosout", move |level, text| {
                let level = match level {
                    Level::Info => ros2_client::log::LogLevel::Info,
                    Level::Warn => ros2_client::log::LogLevel::Warn,
                };
                ros2_client::rosout!(handle, level, "{}", text);
            }));
        }
        Log { lanes }
    }

    /// A log whose lines go to `write` (on its own thread).
    #[cfg(test)]
    fn with_writer(write: impl FnMut(Level, &str) + Send + 'static) -> Log {
        Log {
            lanes: vec![Lane::spawn("log-test", write)],
        }
    }

    /// Queues a line for every writer; never waits.
    pub fn line(&self, level: Level, text: &str) {
        for lane in &self.lanes {
            lane.send((level, text.to_string()));
        }
    }

    pub fn info(&self, text: &str) {
        self.line(Level::Info, text);
    }

    pub fn warn(&self, text: &str) {
        self.line(Level::Warn, text);
    }

    /// Lets the writers write what is queued, waiting at most `within`
    /// (a writer still blocked then is left behind).
    pub fn finish(mut self, within: Duration) {
        let end = Instant::now() + within;
        for lane in &mut self.lanes {
            lane.tx = None;
        }
        for lane in &self.lanes {
            let left = end.saturating_duration_since(Instant::now());
            let _ = lane.done.recv_timeout(left);
        }
    }
}

/// What a message did, as its topic's log tells it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// Applied; what it did (empty: nothing worth a line).
    Applied(String),
    /// Well-formed but refused, and why.
    Refused(String),
    /// Its payload could not be decoded (CDR of another type or cut short).
    Undecodable(String),
}

/// Counts of what a topic held back in the current window.
#[derive(Debug, Default, Clone)]
struct Held {
    applied: u64,
    refused: u64,
    undecodable: u64,
    /// The last refusal held (the reason), if any.
    last_refusal: Option<String>,
}

/// One topic's log lines, bounded in rate; see the module.
#[derive(Debug, Clone)]
pub struct TopicLog {
    topic: String,
    /// When the current window began (`None`: no window open).
    window: Option<Instant>,
    shown: u32,
    held: Held,
}

impl TopicLog {
    pub fn new(topic: &str) -> TopicLog {
        TopicLog {
            topic: topic.to_string(),
            window: None,
            shown: 0,
            held: Held::default(),
        }
    }

    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The line to log now about a message with this outcome, or `None`
    /// if there is nothing to say or the window's [`LOG_FIRST`] lines are
    /// out (it is held for the summary).
    pub fn note(&mut self, now: Instant, outcome: Outcome) -> Option<(Level, String)> {
        if matches!(&outcome, Outcome::Applied(w) if w.is_empty()) {
            return None;
        }
        if self.window.is_none() {
            self.window = Some(now);
            self.shown = 0;
        }
        if self.shown < LOG_FIRST {
            self.shown += 1;
            let topic = &self.topic;
            return Some(match outcome {
                Outcome::Applied(what) => (Level::Info, what),
                Outcome::Refused(why) => {
                    (Level::Warn, format!("rejected message on {topic}: {why}"))
                }
                Outcome::Undecodable(why) => (
                    Level::Warn,
                    format!("rejected message on {topic}: undecodable message (CDR): {why}"),
                ),
            });
        }
        let h = &mut self.held;
        match outcome {
            Outcome::Applied(_) => h.applied += 1,
            Outcome::Refused(why) => {
                h.refused += 1;
                h.last_refusal = Some(why);
            }
            Outcome::Undecodable(why) => {
                h.undecodable += 1;
                h.last_refusal = Some(format!("undecodable message (CDR): {why}"));
            }
        }
        None
    }

    /// Once the window is over: the line summing up what it held back (if
    /// anything); the next message opens a new window.
    pub fn summary(&mut self, now: Instant) -> Option<(Level, String)> {
        let start = self.window?;
        if now.duration_since(start) < LOG_WINDOW {
            return None;
        }
        self.summary_now(now)
    }

    /// The summary of what the open window held back, now (when the node
    /// stops).
    pub fn summary_now(&mut self, now: Instant) -> Option<(Level, String)> {
        let span = now.duration_since(self.window?);
        self.window = None;
        let h = std::mem::take(&mut self.held);
        let n = h.applied + h.refused + h.undecodable;
        if n == 0 {
            return None;
        }
        let mut line = format!(
            "{}: {n} more messages in the last {:.1} s, not logged one by one: \
             {} rejected as undecodable, {} refused, {} applied",
            self.topic,
            span.as_secs_f64(),
            h.undecodable,
            h.refused,
            h.applied
        );
        let level = match h.last_refusal {
            Some(why) => {
                line.push_str(&format!("; the last rejected: {why}"));
                Level::Warn
            }
            None => Level::Info,
        };
        Some((level, line))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A writer that does not take a line (a stderr nobody reads) holds
    /// only its thread: every line is queued or counted as lost at once,
    /// and once it writes again it writes the queue and how many were lost.
    #[test]
    fn a_blocked_writer_never_holds_the_caller() {
        let (release_tx, release) = mpsc::channel::<()>();
        let (blocked_tx, blocked) = mpsc::channel::<()>();
        let (out_tx, out) = mpsc::channel::<String>();
        let mut first = true;
        let log = Log::with_writer(move |_, text| {
            if first {
                first = false;
                let _ = blocked_tx.send(());
                let _ = release.recv();
            }
            let _ = out_tx.send(text.to_string());
        });
        let n = 10_000;
        log.warn("line 0");
        blocked.recv().unwrap();
        for k in 1..n {
            log.warn(&format!("line {k}"));
        }
        // every call above returned while the writer was still blocked on
        // its first line
        release_tx.send(()).unwrap();
        log.finish(Duration::from_secs(10));
        let got: Vec<String> = out.try_iter().collect();
        let written = got.iter().filter(|l| l.starts_with("line ")).count();
        let lost: usize = got
            .iter()
            .filter_map(|l| l.strip_suffix(" log lines not written: they came faster than this log (stderr or /rosout) took them"))
            .map(|n| n.parse::<usize>().unwrap())
            .sum();
        // the first line (taken before blocking) and the queue
        assert_eq!(written, 1 + LOG_QUEUE, "{got:?}");
        assert_eq!(written + lost, n);
        // in order: the lines kept are the first ones
        assert_eq!(got[0], "line 0");
        assert_eq!(got.last().unwrap(), &format!("line {LOG_QUEUE}"));
    }

    #[test]
    fn a_topic_logs_its_first_lines_then_one_summary_a_window() {
        let t0 = Instant::now();
        let mut log = TopicLog::new("/pins");
        let at = |ms: u64| t0 + Duration::from_millis(ms);
        let mut lines = Vec::new();
        // 1000 messages in 0.5 s: half undecodable, a quarter refused, a
        // quarter applied with something to say
        for k in 0..1000u64 {
            let outcome = match k % 4 {
                0 | 1 => Outcome::Undecodable(format!("cut short {k}")),
                2 => Outcome::Refused(format!("NaN {k}")),
                _ => Outcome::Applied(format!("pinned {k}")),
            };
            lines.extend(log.note(at(k / 2), outcome));
            lines.extend(log.summary(at(k / 2)));
        }
        assert_eq!(lines.len(), LOG_FIRST as usize);
        assert_eq!(
            lines[0],
            (
                Level::Warn,
                "rejected message on /pins: undecodable message (CDR): cut short 0".into()
            )
        );
        assert_eq!(lines[3], (Level::Info, "pinned 3".into()));
        // nothing more before the window is over, then one summary
        assert_eq!(log.summary(at(999)), None);
        let (level, s) = log.summary(at(1000)).unwrap();
        assert_eq!(level, Level::Warn);
        assert!(
            s.starts_with(
                "/pins: 995 more messages in the last 1.0 s, not logged one by one: \
                 497 rejected as undecodable, 249 refused, 249 applied"
            ),
            "{s}"
        );
        assert!(s.ends_with("the last rejected: NaN 998"), "{s}");
        assert_eq!(log.summary(at(3000)), None);
        // a new window: the next message is logged one by one again
        let next = log.note(at(5000), Outcome::Refused("far".into()));
        assert_eq!(
            next,
            Some((Level::Warn, "rejected message on /pins: far".into()))
        );
        // applied messages with nothing to say neither log nor count
        assert_eq!(log.note(at(5001), Outcome::Applied(String::new())), None);
        assert_eq!(log.summary(at(6001)), None);
    }
}
