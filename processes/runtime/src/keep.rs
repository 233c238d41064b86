//! What a restarted process resumes from. A process that crashed cannot hand its last output to
//! its successor the way a swapped one does (its publisher died with it), so the launcher keeps
//! the newest sample of every topic a role resumes from ([`LastSamples`], zero-copy: it holds the
//! loaned sample, it copies nothing per step) and, when the role dies, writes those samples into
//! a directory the restarted process is pointed at (`MOLE_RESUME`). The files are the messages'
//! own fixed-layout bytes, one per topic.

use crate::context::Context;
use crate::error::RuntimeError;
use crate::ports::Subscriber;
use crate::waitset::Wake;
use crate::{ClockMode, Waker};
use mole_types::topics::{self, OpenTopic};
use mole_types::{Message, Topic};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, Sender};
use std::time::{Duration, Instant};

/// How often a realtime keeper drains its queues (it is never woken per message there:
/// realtime publishers overwrite a full queue's oldest sample, so nothing waits for it).
const REALTIME_DRAIN: Duration = Duration::from_millis(20);
/// The longest a keeper sleeps before it looks for a request.
const REQUEST_POLL: Duration = Duration::from_millis(10);

/// The file in a resume directory that holds the last sample of `topic`.
pub fn resume_file(dir: &Path, topic: &str) -> PathBuf {
    dir.join(format!("{}.bin", topic.replace('/', ".")))
}

/// Reads the sample of `topic` a restarted process resumes from: `None` when the directory has
/// none (nothing was published before the crash); an error naming the file and what was wrong
/// when it is not one valid message of this type.
pub fn read_resume_file<M: Message>(
    dir: &Path,
    topic: Topic<M>,
) -> Result<Option<Box<M>>, RuntimeError> {
    let path = resume_file(dir, topic.name);
    let bytes = match std::fs::read(&path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(RuntimeError::Resume(path, e.to_string())),
    };
    let size = std::mem::size_of::<M>();
    if bytes.len() != size {
        return Err(RuntimeError::Resume(
            path,
            format!(
                "{} bytes, expected one {} of {size} bytes",
                bytes.len(),
                M::wire_type_name()
            ),
        ));
    }
    let mut message: Box<M> = bytemuck::zeroed_box();
    bytemuck::bytes_of_mut(message.as_mut()).copy_from_slice(&bytes);
    message
        .validate()
        .map_err(|e| RuntimeError::Resume(path, format!("not a valid message: {e:?}")))?;
    Ok(Some(message))
}

/// Writes `message` as the sample of `topic` in `dir`, atomically (a reader never sees half).
fn write_resume_file<M: Message>(dir: &Path, topic: &str, message: &M) -> std::io::Result<()> {
    let path = resume_file(dir, topic);
    let partial = path.with_extension("partial");
    std::fs::write(&partial, bytemuck::bytes_of(message))?;
    std::fs::rename(&partial, &path)
}

/// A request to a [`LastSamples`]: write the kept samples of `topics` into `dir`; the reply is how
/// many were written (topics nothing was published on yet are left out).
pub struct SaveRequest {
    pub topics: Vec<&'static str>,
    pub dir: PathBuf,
    pub reply: Sender<Result<usize, String>>,
}

/// One kept topic, whatever its message type.
trait Kept {
    fn topic(&self) -> &'static str;
    fn drain(&mut self);
    fn waker(&self) -> Waker;
    /// Whether it wakes the keeper.
    fn wakes(&self) -> bool;
    /// Writes the newest sample into `dir`; false when there is none yet.
    fn save(&mut self, dir: &Path) -> std::io::Result<bool>;
}

impl<M: Message> Kept for Subscriber<M> {
    fn topic(&self) -> &'static str {
        Subscriber::topic(self)
    }
    fn drain(&mut self) {
        Subscriber::drain(self, |_| {});
    }
    fn waker(&self) -> Waker {
        Subscriber::waker(self)
    }
    fn wakes(&self) -> bool {
        self.listener.is_some()
    }
    fn save(&mut self, dir: &Path) -> std::io::Result<bool> {
        // The last samples the dead process sent may still be queued.
        Subscriber::drain(self, |_| {});
        match self.latest() {
            Some(message) => write_resume_file(dir, self.topic, message).map(|()| true),
            None => Ok(false),
        }
    }
}

/// Keeps the newest sample of chosen topics of a namespace for restarted processes. It runs on
/// a thread of its own ([`LastSamples::serve`]). In lockstep a full queue would hold its publisher
/// back, so it drains every queue each time the clock's topic (published once a step) wakes it:
/// every kept topic is published at most once a step, and one wake-up a step costs the loop far
/// less than one per topic (a wake-up per message took 35% off lockstep's steps/s). In realtime
/// it is never woken and drains every [`REALTIME_DRAIN`].
pub struct LastSamples {
    ctx: Context,
    kept: Vec<Box<dyn Kept>>,
}

impl LastSamples {
    /// A keeper of `names` (topics of `mole_types::topics`) on its own node, woken in lockstep
    /// by `clock` (one of them, published once a step); it publishes no statistics (it is part
    /// of the launcher, not a role).
    pub fn new(mut ctx: Context, names: &[&str], clock: &str) -> Result<LastSamples, RuntimeError> {
        ctx.silence_stats();
        struct Open<'a> {
            ctx: &'a Context,
            clock: &'a str,
        }
        impl OpenTopic for Open<'_> {
            type Port = Box<dyn Kept>;
            type Error = RuntimeError;
            fn open<M: Message>(&mut self, topic: Topic<M>) -> Result<Self::Port, RuntimeError> {
                let wakes = self.ctx.mode() == ClockMode::Lockstep && topic.name == self.clock;
                Ok(match wakes {
                    true => Box::new(self.ctx.subscriber(topic)?),
                    false => Box::new(self.ctx.passive_subscriber(topic)?),
                })
            }
        }
        let wanted = |name: &str| names.contains(&name);
        let kept = topics::open_each(wanted, &mut Open { ctx: &ctx, clock })?;
        if let Some(unknown) = names
            .iter()
            .find(|n| !kept.iter().any(|k| k.topic() == **n))
        {
            return Err(RuntimeError::Setting(format!(
                "cannot keep `{unknown}`: not a topic of the stack"
            )));
        }
        Ok(LastSamples { ctx, kept })
    }

    /// Keeps the newest samples and answers `requests` until the shutdown flag is set or the
    /// requests' sender is gone.
    pub fn serve(mut self, requests: Receiver<SaveRequest>) -> Result<(), RuntimeError> {
        let waitset = self.ctx.waitset()?;
        let lockstep = self.ctx.mode() == ClockMode::Lockstep;
        let wakers: Vec<Waker> = self
            .kept
            .iter()
            .filter(|k| k.wakes())
            .map(|k| k.waker())
            .collect();
        let _attached = waitset.attach_all(&wakers)?;
        let mut next_drain = Instant::now();
        loop {
            let wake = waitset.wait(&mut self.ctx, Some(Instant::now() + REQUEST_POLL))?;
            if wake == Wake::Shutdown {
                return Ok(());
            }
            if lockstep || Instant::now() >= next_drain {
                self.kept.iter_mut().for_each(|k| k.drain());
                next_drain = Instant::now() + REALTIME_DRAIN;
            }
            loop {
                match requests.try_recv() {
                    Ok(request) => {
                        let _ = request.reply.send(self.save(&request.topics, &request.dir));
                    }
                    Err(std::sync::mpsc::TryRecvError::Empty) => break,
                    Err(std::sync::mpsc::TryRecvError::Disconnected) => return Ok(()),
                }
            }
        }
    }

    fn save(&mut self, topics: &[&'static str], dir: &Path) -> Result<usize, String> {
        let failed = |e: std::io::Error| format!("{}: {e}", dir.display());
        std::fs::create_dir_all(dir).map_err(failed)?;
        let mut written = 0;
        for kept in self.kept.iter_mut().filter(|k| topics.contains(&k.topic())) {
            written += usize::from(kept.save(dir).map_err(failed)?);
        }
        Ok(written)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mole_types::Pose;

    fn dir(test: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("mole-keep-{test}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("a directory");
        dir
    }

    /// What is written is read back as it was; a topic with no file is nothing to resume.
    #[test]
    fn a_written_sample_reads_back_and_a_missing_one_is_none() {
        let dir = dir("roundtrip");
        let mut pose: Box<Pose> = bytemuck::zeroed_box();
        (pose.header.tick, pose.x, pose.y) = (41, 1.5, -2.0);
        pose.estimator = mole_types::EstimatorKind::Ekf.code();
        write_resume_file(&dir, topics::LOCALIZATION_POSE.name, &*pose).expect("written");
        let read = read_resume_file(&dir, topics::LOCALIZATION_POSE).expect("valid");
        assert_eq!(read.as_deref(), Some(&*pose));
        assert!(
            !dir.join("localization.pose.partial").exists(),
            "written atomically"
        );
        let missing = read_resume_file(&dir, topics::WORLD_TRUTH).expect("no error");
        assert!(missing.is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A file of the wrong size or with invalid values is an error naming the file and what
    /// was wrong (the process exits 2 on it), never a sample.
    #[test]
    fn a_file_of_the_wrong_size_or_with_invalid_values_is_refused_naming_it() {
        let dir = dir("bad");
        let path = resume_file(&dir, topics::LOCALIZATION_POSE.name);
        std::fs::write(&path, b"not a pose").expect("written");
        let short = read_resume_file(&dir, topics::LOCALIZATION_POSE).expect_err("refused");
        let RuntimeError::Resume(named, why) = &short else {
            panic!("{short:?}")
        };
        assert_eq!(named, &path);
        assert!(why.starts_with("10 bytes, expected one"), "{why}");
        let mut pose: Box<Pose> = bytemuck::zeroed_box();
        pose.estimator = mole_types::EstimatorKind::Ekf.code();
        pose.x = f64::NAN;
        write_resume_file(&dir, topics::LOCALIZATION_POSE.name, &*pose).expect("written");
        let invalid = read_resume_file(&dir, topics::LOCALIZATION_POSE).expect_err("refused");
        assert!(
            matches!(&invalid, RuntimeError::Resume(p, why) if p == &path && why.starts_with("not a valid message")),
            "{invalid:?}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }
}
