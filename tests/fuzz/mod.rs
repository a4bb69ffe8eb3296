//! Fuzzing every parser of a file mousepose reads, on the stable toolchain: a small mutation
//! fuzzer (`mutate`) over seed inputs written by mousepose's own writers (`targets`), feeding
//! the real readers through files in a scratch directory.
//!
//! A target passes an input when the reader returns a clean error or a value that holds up
//! (frames of the size they claim, trees that can be walked, a cascade that can be run, every
//! byte of a record file accounted for once), and fails it on a panic, on a value that does not
//! hold up, on an input that runs past [`HANG_SECS`] (a hang), or on one that makes the process
//! allocate beyond its memory budget (the campaign lowers its own data limit, so such an
//! allocation aborts the process).
//!
//! A campaign runs in a process of its own, the ignored test [`campaign`], driven by
//! environment variables (`MOUSEPOSE_FUZZ_TARGET`, `_SEED`, `_RUNS` or `_SECONDS`, `_OUT`,
//! `_MEMORY_MB`): the suite's tests below start it for a few hundred inputs of each target with
//! a fixed seed; `scripts/fuzz MINUTES [TARGET]` for long runs. Inputs whose outcome (the error
//! met, or the shape of the value) was not seen before join the corpus, which is kept in
//! `OUT/corpus/` between runs; failing inputs are written to `OUT/crashes/`, and an input that
//! killed the process stays in `OUT/work/`.

mod mutate;
mod targets;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::HashSet;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// An input that runs longer than this is a hang.
pub const HANG_SECS: u64 = 20;
/// The memory a campaign may allocate beyond what it holds when it starts (MiB).
const DEFAULT_MEMORY_MB: u64 = 1024;
/// Inputs in the corpus at most, in memory (the seeds always stay) and on disk.
const MAX_CORPUS: usize = 2000;
/// Bytes the corpus holds in memory at most, and the largest input it takes in: the
/// campaign's own memory stays far below the data limit that catches the readers'.
const MAX_CORPUS_BYTES: usize = 128 << 20;
const MAX_CORPUS_INPUT_BYTES: usize = 1 << 20;

/// One fuzz input: named parts, most of them files written under the work directory by that
/// relative path; parts whose name starts with `@` are read by the target itself (a mode, a
/// section that it assembles into a file).
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct Input {
    pub parts: Vec<(String, Vec<u8>)>,
}

impl Input {
    fn id(&self) -> String {
        let mut h = DefaultHasher::new();
        self.hash(&mut h);
        format!("{:016x}", h.finish())
    }

    /// The bytes of part `name` (empty when there is none).
    pub fn part(&self, name: &str) -> &[u8] {
        self.parts.iter().find(|p| p.0 == name).map_or(&[], |p| &p.1)
    }

    fn total_bytes(&self) -> usize {
        self.parts.iter().map(|p| p.1.len()).sum()
    }

    /// Writes every file part under `dir`, emptied first.
    pub fn write_files(&self, dir: &Path) -> std::io::Result<()> {
        if dir.exists() {
            std::fs::remove_dir_all(dir)?;
        }
        std::fs::create_dir_all(dir)?;
        for (name, bytes) in self.parts.iter().filter(|p| !p.0.starts_with('@')) {
            write_part(dir, name, bytes)?;
        }
        Ok(())
    }

    /// Saves every part (control parts included) as a file under `dir`.
    fn save(&self, dir: &Path) -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        for (name, bytes) in &self.parts {
            write_part(dir, name, bytes)?;
        }
        Ok(())
    }

    /// Reads an input saved by [`Input::save`]: the files under `dir`, by relative path.
    fn load(dir: &Path) -> std::io::Result<Self> {
        let mut parts = Vec::new();
        collect(dir, dir, &mut parts)?;
        parts.sort();
        Ok(Self { parts })
    }
}

fn write_part(dir: &Path, name: &str, bytes: &[u8]) -> std::io::Result<()> {
    let path = dir.join(name);
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent)?;
    }
    std::fs::write(path, bytes)
}

fn collect(root: &Path, dir: &Path, out: &mut Vec<(String, Vec<u8>)>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            collect(root, &path, out)?;
        } else if let Ok(rel) = path.strip_prefix(root) {
            out.push((rel.to_string_lossy().into_owned(), std::fs::read(&path)?));
        }
    }
    Ok(())
}

/// What running one input gave: `Ok` with its outcome (an error's text with numbers and the
/// directory left out, or the shape of the value read), `Err` with why the value read does
/// not hold up.
pub type Outcome = Result<String, String>;

/// A parser under test.
pub struct Target {
    pub name: &'static str,
    /// The seed inputs, made by mousepose's writers; `scratch` is an empty directory to make
    /// them in.
    pub seeds: fn(scratch: &Path) -> Vec<Input>,
    /// Writes the input under `dir` and reads it with the parser.
    pub run: fn(input: &Input, dir: &Path) -> Outcome,
    /// Extra words for the mutator besides those of the seeds.
    pub words: &'static [&'static str],
}

/// An error's whole chain as an outcome: its words, with numbers and quoted text (paths, keys
/// and values from the input) left out, so that outcomes tell apart the checks that failed
/// rather than the inputs.
pub fn outcome_of(e: &dyn std::error::Error, dir: &Path) -> String {
    let text = mousepose::core::error_chain(e).replace(&dir.display().to_string(), "DIR");
    let mut out = String::with_capacity(text.len());
    let mut quote = None;
    for c in text.chars() {
        match quote {
            Some(q) if c == q => {
                out.push(c);
                quote = None;
            }
            Some(_) => {}
            None if c == '"' || c == '`' => {
                out.push(c);
                quote = Some(c);
            }
            None if c.is_ascii_digit() => {
                if !out.ends_with('#') {
                    out.push('#');
                }
            }
            None => out.push(c),
        }
    }
    format!("err: {out}")
}

fn env(name: &str) -> Option<String> {
    std::env::var(format!("MOUSEPOSE_FUZZ_{name}")).ok()
}

fn env_u64(name: &str, default: u64) -> u64 {
    env(name).and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Lowers the process's data limit to what it holds now plus `budget_mb`, so that an input
/// making the parser allocate more aborts the campaign instead of going unnoticed.
fn limit_memory(budget_mb: u64) {
    use rustix::process::{Resource, Rlimit, getrlimit, setrlimit};
    let want = (data_kb() << 10) + (budget_mb << 20);
    let old = getrlimit(Resource::Data);
    let limit = old.maximum.map_or(want, |max| max.min(want));
    let result = setrlimit(
        Resource::Data,
        Rlimit {
            current: Some(limit),
            maximum: old.maximum,
        },
    );
    assert!(result.is_ok(), "cannot lower the data limit: {result:?}");
}

/// A figure of `/proc/self/status` in KiB (0 when it cannot be read).
fn status_kb(key: &str) -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix(key))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// The process's data (heap and private mappings), what the data limit counts (KiB).
fn data_kb() -> u64 {
    status_kb("VmData:")
}

/// Peak resident memory since [`reset_peak_rss`] (KiB).
fn peak_rss_kb() -> u64 {
    status_kb("VmHWM:")
}

/// Starts the peak resident memory figure again from what is resident now (Linux's
/// `clear_refs` 5).
fn reset_peak_rss() {
    // Best effort: without it the figure is the campaign's peak, still an upper bound.
    if std::fs::write("/proc/self/clear_refs", "5").is_err() {
        eprintln!("fuzz: cannot reset the peak memory figure");
    }
}

/// A thread that ends the process when one input has run longer than [`HANG_SECS`]: the input
/// is then in the work directory.
fn watchdog(started_ms: Arc<AtomicU64>, epoch: Instant, work: PathBuf) {
    let spawned = std::thread::Builder::new()
        .name("fuzz-watchdog".to_owned())
        .spawn(move || {
            loop {
                std::thread::sleep(Duration::from_millis(200));
                let started = started_ms.load(Ordering::Relaxed);
                let now = epoch.elapsed().as_millis() as u64;
                if started > 0 && now.saturating_sub(started) > HANG_SECS * 1000 {
                    eprintln!(
                        "fuzz: an input ran longer than {HANG_SECS} s (a hang); it is in {}",
                        work.display()
                    );
                    std::process::exit(3);
                }
            }
        });
    assert!(spawned.is_ok(), "cannot start the watchdog");
}

/// The campaign's settings, from the environment.
struct Settings {
    target: &'static Target,
    seed: u64,
    runs: Option<u64>,
    seconds: Option<u64>,
    out: PathBuf,
}

/// One campaign, as the environment says. Run alone in its own process (it lowers the
/// process's data limit): `cargo test --test tests fuzz::campaign -- --ignored --exact`.
#[test]
#[ignore = "a fuzz campaign, started by the fuzz tests and scripts/fuzz with its settings in the environment"]
fn campaign() {
    let name = env("TARGET").expect("MOUSEPOSE_FUZZ_TARGET names the target");
    let target = targets::ALL
        .iter()
        .find(|t| t.name == name)
        .unwrap_or_else(|| panic!("no fuzz target {name:?}; targets: {}", target_names()));
    let settings = Settings {
        target,
        seed: env_u64("SEED", 1),
        runs: env("RUNS").and_then(|v| v.parse().ok()),
        seconds: env("SECONDS").and_then(|v| v.parse().ok()),
        out: PathBuf::from(env("OUT").expect("MOUSEPOSE_FUZZ_OUT names the output directory")),
    };
    let failures = run_campaign(&settings);
    assert_eq!(
        failures,
        0,
        "{failures} failing inputs, saved in {}",
        settings.out.join("crashes").display()
    );
}

fn target_names() -> String {
    targets::ALL.iter().map(|t| t.name).collect::<Vec<_>>().join(", ")
}

fn run_campaign(s: &Settings) -> u64 {
    let t = s.target;
    let work = s.out.join("work");
    let corpus_dir = s.out.join("corpus");
    let crashes = s.out.join("crashes");
    let scratch = s.out.join("seeds");
    for dir in [&corpus_dir, &crashes] {
        std::fs::create_dir_all(dir).expect("output directory");
    }
    if scratch.exists() {
        std::fs::remove_dir_all(&scratch).expect("old seed directory");
    }
    std::fs::create_dir_all(&scratch).expect("seed directory");
    let seeds = (t.seeds)(&scratch);
    assert!(!seeds.is_empty(), "target {} has no seeds", t.name);
    let mut words = mutate::words_of(&seeds);
    words.extend(t.words.iter().map(|w| w.as_bytes().to_vec()));

    let budget_mb = env_u64("MEMORY_MB", DEFAULT_MEMORY_MB);
    limit_memory(budget_mb);
    let epoch = Instant::now();
    let started_ms = Arc::new(AtomicU64::new(0));
    watchdog(started_ms.clone(), epoch, work.clone());

    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let mut seen = HashSet::new();
    let mut corpus = Vec::new();
    let mut failures = 0u64;
    let mut runs = 0u64;
    let mut slowest = (Duration::ZERO, 0usize);
    let mut biggest = (0u64, 0usize);
    // Runs one input: its outcome, `None` when it failed.
    let mut run_one = |input: &Input| -> Option<String> {
        started_ms.store(epoch.elapsed().as_millis().max(1) as u64, Ordering::Relaxed);
        reset_peak_rss();
        let before = peak_rss_kb();
        let t0 = Instant::now();
        let result = catch_unwind(AssertUnwindSafe(|| (t.run)(input, &work)));
        let took = t0.elapsed();
        let grew_kb = peak_rss_kb().saturating_sub(before);
        started_ms.store(0, Ordering::Relaxed);
        if took > slowest.0 {
            slowest = (took, input.total_bytes());
        }
        if grew_kb > biggest.0 {
            biggest = (grew_kb, input.total_bytes());
        }
        let verdict = match result {
            Ok(Ok(outcome)) => Ok(outcome),
            Ok(Err(why)) => Err(format!("a value read does not hold up: {why}")),
            Err(panic) => Err(format!(
                "panic: {}",
                panic
                    .downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| panic.downcast_ref::<&str>().copied())
                    .unwrap_or("(no message)")
            )),
        };
        match verdict {
            Ok(outcome) => Some(outcome),
            Err(why) => {
                let dir = crashes.join(format!("{}-{}", t.name, input.id()));
                eprintln!("fuzz {}: failing input saved in {}: {why}", t.name, dir.display());
                if let Err(e) = input
                    .save(&dir)
                    .and_then(|()| std::fs::write(dir.join("@why.txt"), &why))
                {
                    eprintln!("fuzz: cannot save the failing input: {e}");
                }
                None
            }
        }
    };

    for seed in &seeds {
        let outcome = run_one(seed);
        let outcome = outcome.unwrap_or_else(|| panic!("a seed input of {} fails", t.name));
        eprintln!("fuzz {}: seed {outcome}", t.name);
        seen.insert(outcome);
        runs += 1;
        corpus.push(seed.clone());
    }
    let seed_count = corpus.len();
    // The corpus kept by earlier campaigns, within the corpus's bounds.
    let mut corpus_bytes: usize = corpus.iter().map(Input::total_bytes).sum();
    if let Ok(entries) = std::fs::read_dir(&corpus_dir) {
        let mut dirs: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        dirs.sort();
        for dir in dirs {
            if let Ok(input) = Input::load(&dir)
                && input.total_bytes() <= MAX_CORPUS_INPUT_BYTES
                && corpus_bytes + input.total_bytes() <= MAX_CORPUS_BYTES
            {
                corpus_bytes += input.total_bytes();
                match run_one(&input) {
                    Some(outcome) => {
                        seen.insert(outcome);
                    }
                    None => failures += 1,
                }
                runs += 1;
                corpus.push(input);
            }
        }
    }
    let kept = corpus.len() - seed_count;
    let mut on_disk = kept;
    let stop_at = s.seconds.map(|secs| epoch + Duration::from_secs(secs));
    let data_at_start = data_kb();
    let mut leaked = false;
    loop {
        if s.runs.is_some_and(|n| runs >= n) || stop_at.is_some_and(|at| Instant::now() >= at) {
            break;
        }
        // Memory that stays taken after its input (a leak in a reader or a library under it,
        // or freed memory the allocator keeps) would end the campaign at the data limit: stop
        // first and say so.
        if runs % 1000 == 0 && data_kb().saturating_sub(data_at_start) > (budget_mb << 10) / 2 {
            eprintln!(
                "fuzz {}: stopping early: the process's data grew by {} MiB over {runs} inputs (memory kept after its input)",
                t.name,
                data_kb().saturating_sub(data_at_start) >> 10
            );
            leaked = true;
            break;
        }
        let mut input = corpus[rng.gen_range(0..corpus.len())].clone();
        mutate::mutate(&mut input, &corpus, &words, &mut rng);
        let outcome = run_one(&input);
        runs += 1;
        failures += u64::from(outcome.is_none());
        if input.total_bytes() <= MAX_CORPUS_INPUT_BYTES && outcome.is_some_and(|o| seen.insert(o)) {
            while corpus.len() > seed_count
                && (corpus.len() >= MAX_CORPUS || corpus_bytes + input.total_bytes() > MAX_CORPUS_BYTES)
            {
                let evict = rng.gen_range(seed_count..corpus.len());
                corpus_bytes -= corpus.swap_remove(evict).total_bytes();
            }
            corpus_bytes += input.total_bytes();
            if on_disk < MAX_CORPUS {
                on_disk += 1;
                if let Err(e) = input.save(&corpus_dir.join(input.id())) {
                    eprintln!("fuzz: cannot keep an input in the corpus: {e}");
                }
            }
            corpus.push(input);
        }
    }
    // Only a campaign that died leaves its last input in the work directory.
    if let Err(e) = std::fs::remove_dir_all(&work) {
        eprintln!("fuzz: cannot remove {}: {e}", work.display());
    }
    let secs = epoch.elapsed().as_secs_f64();
    eprintln!(
        "fuzz {}: {runs} inputs in {secs:.1} s, {} outcomes, corpus {} ({} seeds, {kept} kept from earlier runs), \
         {failures} failing; slowest input {:.0} ms ({} bytes), largest memory peak {} KiB ({} bytes)",
        t.name,
        seen.len(),
        corpus.len(),
        seed_count,
        slowest.0.as_secs_f64() * 1e3,
        slowest.1,
        biggest.0,
        biggest.1,
    );
    let log = format!(
        "{} seed={} inputs={runs} seconds={secs:.1} failing={failures} leaking={}\n",
        t.name,
        s.seed,
        u8::from(leaked)
    );
    let appended = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(s.out.join("runs.log"))
        .and_then(|mut f| std::io::Write::write_all(&mut f, log.as_bytes()));
    if let Err(e) = appended {
        eprintln!("fuzz: cannot append to runs.log: {e}");
    }
    failures
}

/// Runs a short campaign of `target` in a child process (its own data limit and watchdog)
/// and fails when it finds a failing input.
fn short_campaign(target: &str, runs: u64) {
    let out = tempfile::tempdir().expect("temporary directory");
    let exe = std::env::current_exe().expect("the test binary");
    let output = Command::new(exe)
        .args([
            "fuzz::campaign",
            "--exact",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("MOUSEPOSE_FUZZ_TARGET", target)
        .env("MOUSEPOSE_FUZZ_SEED", "1")
        .env("MOUSEPOSE_FUZZ_RUNS", runs.to_string())
        .env("MOUSEPOSE_FUZZ_OUT", out.path())
        .output()
        .expect("runs the fuzz campaign");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        output.status.success() && stderr.contains(&format!("fuzz {target}: {runs} inputs")),
        "fuzz campaign of {target} failed ({}):\n{stdout}\n{stderr}",
        output.status
    );
}

#[test]
fn fuzz_store() {
    short_campaign("store", 1500);
}

#[test]
fn fuzz_session() {
    short_campaign("session", 400);
}

#[test]
fn fuzz_moseq() {
    short_campaign("moseq", 1500);
}

#[test]
fn fuzz_forest() {
    short_campaign("forest", 600);
}

#[test]
fn fuzz_cascade() {
    short_campaign("cascade", 800);
}

#[test]
fn fuzz_calibration() {
    short_campaign("calibration", 800);
}

#[test]
fn fuzz_config() {
    short_campaign("config", 1500);
}
