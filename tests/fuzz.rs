//! Bounded fuzzing of every loader a user feeds psrestir: glTF (JSON), GLB, the task TOML,
//! PNG and JPEG textures, Radiance HDR and OpenEXR images.
//!
//! Each target starts from a seed corpus made from the repository's scenes and mutates it:
//! structure-aware for JSON and TOML (values replaced by boundary values, keys removed, subtrees
//! moved), byte-level for everything, with PNG chunk checksums repaired so that mutations reach
//! the decoder. An input whose outcome is new (accepted, or refused with a message not seen
//! before) joins the corpus, a cheap stand-in for coverage feedback. Every input runs with:
//! - panics caught: the input is saved under `target/fuzz-findings/<target>/` and the test fails;
//! - a watchdog: an input that runs longer than [`HANG_S`] is saved and the process exits;
//! - its peak heap allocation measured by a counting allocator and bounded by
//!   [`MEMORY_BOUND`]; allocations past [`HARD_CAP`] fail (a loader that uses `try_reserve`
//!   sees an error, one that does not aborts).
//!
//! Inputs kept in `tests/fuzz_regressions/<target>/` (earlier findings) are replayed first.
//!
//! `PSRESTIR_FUZZ_SECONDS` sets the time per target (default 8 s), `PSRESTIR_FUZZ_SEED` the
//! random seed (default 1). The inputs depend only on the seed, so a shorter run replays a
//! prefix of a longer one: the test suite's run with the default seed is a prefix of runs that
//! passed, and new ground is covered by long runs with other seeds:
//! `PSRESTIR_FUZZ_SEED=$RANDOM PSRESTIR_FUZZ_SECONDS=600 cargo test --release --test fuzz -- --nocapture`.
mod common;

use common::crc32;
use psrestir::assets::authoring::glb_bytes;
use psrestir::image_io::decode as images;
use psrestir::job::Problem;
use psrestir::scene::{self, bvh, EnvMap};
use psrestir::task::Task;
use serde_json::Value;
use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::HashSet;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering::Relaxed};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};

/// Longest time one input may take (seconds). The slowest seeds load in well under a second
/// in a debug build.
const HANG_S: u64 = 20;
/// Largest peak heap allocation one input may cause. The seeds need under 40 MiB. Image
/// decoders refuse a declared size above `MAX_EXPANSION` (4200) times the file's size, so the
/// mutated files (under about 50 kB) cannot ask for more than about 200 MiB of pixels.
const MEMORY_BOUND: usize = 512 << 20;
/// Allocations beyond this many live bytes fail.
const HARD_CAP: usize = 4 << 30;

// ---- Counting allocator ----------------------------------------------------------------

struct Counting;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

impl Counting {
    fn grow(&self, n: usize) -> bool {
        let now = LIVE.fetch_add(n, Relaxed) + n;
        if now > HARD_CAP {
            LIVE.fetch_sub(n, Relaxed);
            return false;
        }
        PEAK.fetch_max(now, Relaxed);
        true
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        if !self.grow(l.size()) {
            return std::ptr::null_mut();
        }
        let p = System.alloc(l);
        if p.is_null() {
            LIVE.fetch_sub(l.size(), Relaxed);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        if !self.grow(l.size()) {
            return std::ptr::null_mut();
        }
        let p = System.alloc_zeroed(l);
        if p.is_null() {
            LIVE.fetch_sub(l.size(), Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l);
        LIVE.fetch_sub(l.size(), Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        if new > l.size() && !self.grow(new - l.size()) {
            return std::ptr::null_mut();
        }
        let q = System.realloc(p, l, new);
        if q.is_null() {
            if new > l.size() {
                LIVE.fetch_sub(new - l.size(), Relaxed);
            }
        } else if new < l.size() {
            LIVE.fetch_sub(l.size() - new, Relaxed);
        }
        q
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

// ---- Random numbers ----------------------------------------------------------------------

/// SplitMix64.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn chance(&mut self, p: f64) -> bool {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }
    fn pick<'a, T>(&mut self, v: &'a [T]) -> &'a T {
        &v[self.below(v.len())]
    }
}

// ---- Byte mutations ----------------------------------------------------------------------

const INTERESTING_U32: [u32; 14] = [
    0,
    1,
    2,
    3,
    4,
    7,
    16,
    255,
    256,
    0x7fff,
    0xffff,
    0x7fff_ffff,
    0x8000_0000,
    0xffff_ffff,
];

/// One to four byte-level edits: bit flips, boundary bytes and words (either endianness),
/// deletions, duplications, insertions, a splice from another corpus entry, truncation.
fn mutate_bytes(rng: &mut Rng, data: &mut Vec<u8>, corpus: &[Vec<u8>]) {
    for _ in 0..1 + rng.below(4) {
        let n = data.len();
        match rng.below(9) {
            0 if n > 0 => {
                let i = rng.below(n);
                data[i] ^= 1 << rng.below(8);
            }
            1 if n > 0 => {
                let i = rng.below(n);
                data[i] = *rng.pick(&[0u8, 1, 0x7f, 0x80, 0xff, b'0', b'9', b'-', b'"']);
            }
            2 if n >= 4 => {
                let i = rng.below(n - 3);
                let v = *rng.pick(&INTERESTING_U32);
                let b = if rng.chance(0.5) {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                data[i..i + 4].copy_from_slice(&b);
            }
            3 if n > 0 => {
                let i = rng.below(n);
                let len = (1 + rng.below(64)).min(n - i);
                data.drain(i..i + len);
            }
            4 if n > 0 => {
                let i = rng.below(n);
                let len = (1 + rng.below(256)).min(n - i);
                let chunk = data[i..i + len].to_vec();
                let at = rng.below(n + 1);
                data.splice(at..at, chunk);
            }
            5 => {
                let at = rng.below(n + 1);
                let len = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..len).map(|_| rng.next() as u8).collect();
                data.splice(at..at, bytes);
            }
            6 if !corpus.is_empty() => {
                let other = rng.pick(corpus);
                if !other.is_empty() {
                    let i = rng.below(other.len());
                    let len = (1 + rng.below(512)).min(other.len() - i);
                    let at = rng.below(n + 1);
                    let end = (at + len).min(n);
                    data.splice(at..end, other[i..i + len].iter().copied());
                }
            }
            7 if n > 0 => data.truncate(rng.below(n)),
            _ if n > 0 => {
                // Add a small delta to a byte (counts, lengths, enum values).
                let i = rng.below(n);
                data[i] = data[i].wrapping_add((rng.below(33) as u8).wrapping_sub(16));
            }
            _ => data.push(rng.next() as u8),
        }
    }
}

/// Recompute the CRC of every PNG chunk whose length still fits in the file, so that the
/// decoder looks past the checksum.
fn fix_png_crcs(data: &mut [u8]) {
    let mut at = 8;
    while at + 12 <= data.len() {
        let len = u32::from_be_bytes(data[at..at + 4].try_into().unwrap()) as usize;
        let Some(end) = (at + 8).checked_add(len).filter(|e| e + 4 <= data.len()) else {
            break;
        };
        let crc = crc32(&data[at + 4..end]);
        data[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

// ---- Structured mutations ----------------------------------------------------------------

fn interesting_json(rng: &mut Rng) -> Value {
    use serde_json::json;
    let pool = [
        json!(0),
        json!(-1),
        json!(1),
        json!(2),
        json!(3),
        json!(4),
        json!(6),
        json!(5121),
        json!(5123),
        json!(5125),
        json!(5126),
        json!(34962),
        json!(65535),
        json!(4294967295u64),
        json!(4294967296u64),
        json!(9007199254740993u64),
        json!(1e38),
        json!(-1e38),
        json!(1e-40),
        json!(0.5),
        json!(f64::MAX),
        json!(""),
        json!("SCALAR"),
        json!("VEC2"),
        json!("VEC3"),
        json!("MAT4"),
        json!("data:application/octet-stream;base64,AAAAAAAAAAAAAAAA"),
        json!("data:,"),
        json!("scene.bin"),
        json!("../scene.bin"),
        json!("/etc/passwd"),
        json!("%2e%2e/x"),
        json!("floor.png"),
        json!("sky.exr"),
        json!("image/png"),
        json!("point"),
        json!("spot"),
        json!("directional"),
        json!("perspective"),
        json!(null),
        json!(true),
        json!([]),
        json!({}),
        json!([0, 0, 0]),
        json!([1e30, -1e30, 0]),
        json!([0.0, 0.0, 0.0, 0.0]),
        json!([1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]),
    ];
    rng.pick(&pool).clone()
}

/// JSON pointers to every value under `v`.
fn json_paths(v: &Value, at: String, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, c) in m {
                let p = format!("{at}/{}", k.replace('~', "~0").replace('/', "~1"));
                json_paths(c, p, out);
            }
        }
        Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                json_paths(c, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
    out.push(at);
}

/// One to four edits of a JSON document: a value replaced by a boundary value, a number
/// nudged, a key or element removed, an element duplicated, a subtree moved.
fn mutate_json(rng: &mut Rng, doc: &mut Value) {
    for _ in 0..1 + rng.below(4) {
        let mut paths = Vec::new();
        json_paths(doc, String::new(), &mut paths);
        let path = rng.pick(&paths).clone();
        if path.is_empty() {
            continue;
        }
        let op = rng.below(6);
        if op == 4 {
            // Remove the value from its parent.
            let (parent, key) = path.rsplit_once('/').unwrap();
            let key = key.replace("~1", "/").replace("~0", "~");
            match doc.pointer_mut(parent) {
                Some(Value::Object(m)) => {
                    m.remove(&key);
                }
                Some(Value::Array(a)) => {
                    if let Ok(i) = key.parse::<usize>() {
                        if i < a.len() {
                            a.remove(i);
                        }
                    }
                }
                _ => {}
            }
            continue;
        }
        let donor = doc
            .pointer(rng.pick(&paths).as_str())
            .cloned()
            .unwrap_or(Value::Null);
        let Some(slot) = doc.pointer_mut(&path) else {
            continue;
        };
        match op {
            0 | 1 => *slot = interesting_json(rng),
            2 => {
                if let Some(x) = slot.as_f64() {
                    let y = match rng.below(5) {
                        0 => x + 1.0,
                        1 => x - 1.0,
                        2 => -x,
                        3 => x * 1024.0,
                        _ => x * 65536.0 * 65536.0,
                    };
                    *slot = if y.fract() == 0.0 && y.abs() < 9e15 {
                        Value::from(y as i64)
                    } else {
                        Value::from(y)
                    };
                } else {
                    *slot = interesting_json(rng);
                }
            }
            3 => {
                if let Value::Array(a) = slot {
                    if !a.is_empty() {
                        let e = a[rng.below(a.len())].clone();
                        for _ in 0..1 + rng.below(3) {
                            a.push(e.clone());
                        }
                    }
                } else {
                    *slot = donor;
                }
            }
            _ => *slot = donor,
        }
    }
}

fn interesting_toml(rng: &mut Rng) -> toml::Value {
    use toml::Value as T;
    let pool = [
        T::Integer(0),
        T::Integer(-1),
        T::Integer(1),
        T::Integer(2),
        T::Integer(4096),
        T::Integer(8192),
        T::Integer(65536),
        T::Integer(1 << 31),
        T::Integer(1 << 32),
        T::Integer(i64::MAX),
        T::Integer(i64::MIN),
        T::Float(0.0),
        T::Float(-0.5),
        T::Float(1e300),
        T::Float(f64::NAN),
        T::Float(f64::INFINITY),
        T::Float(f64::NEG_INFINITY),
        T::String(String::new()),
        T::String("scene.gltf".into()),
        T::String("../scene.gltf".into()),
        T::String("/nonexistent/scene.gltf".into()),
        T::String("sky.exr".into()),
        T::String("floor.png".into()),
        T::String("task.toml".into()),
        T::String("base_color".into()),
        T::String("metallic".into()),
        T::String("roughness".into()),
        T::String("sphere".into()),
        T::String("floor".into()),
        T::String("main".into()),
        T::String("nearest".into()),
        T::String("l1".into()),
        T::String("restir".into()),
        T::Boolean(true),
        T::Array(vec![]),
        T::Array(vec![T::Integer(1), T::Integer(1)]),
        T::Array(vec![T::Integer(8192), T::Integer(8192)]),
        T::Array(vec![T::Integer(0), T::Integer(4)]),
        T::Array(vec![T::Float(f64::NAN), T::Float(2.0), T::Float(-1.0)]),
        T::Table(Default::default()),
    ];
    rng.pick(&pool).clone()
}

fn toml_paths(v: &toml::Value, at: Vec<String>, out: &mut Vec<Vec<String>>) {
    match v {
        toml::Value::Table(t) => {
            for (k, c) in t {
                let mut p = at.clone();
                p.push(k.clone());
                toml_paths(c, p, out);
            }
        }
        toml::Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                let mut p = at.clone();
                p.push(i.to_string());
                toml_paths(c, p, out);
            }
        }
        _ => {}
    }
    out.push(at);
}

fn toml_at<'a>(v: &'a mut toml::Value, path: &[String]) -> Option<&'a mut toml::Value> {
    let mut cur = v;
    for k in path {
        cur = match cur {
            toml::Value::Table(t) => t.get_mut(k)?,
            toml::Value::Array(a) => a.get_mut(k.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    Some(cur)
}

/// One to three edits of a TOML document, as [`mutate_json`] does for JSON.
fn mutate_toml(rng: &mut Rng, doc: &mut toml::Value) {
    for _ in 0..1 + rng.below(3) {
        let mut paths = Vec::new();
        toml_paths(doc, Vec::new(), &mut paths);
        let path = rng.pick(&paths).clone();
        let Some((key, parent)) = path.split_last() else {
            continue;
        };
        match rng.below(4) {
            0 => match toml_at(doc, parent) {
                Some(toml::Value::Table(t)) => {
                    t.remove(key);
                }
                Some(toml::Value::Array(a)) => {
                    if let Ok(i) = key.parse::<usize>() {
                        if i < a.len() {
                            a.remove(i);
                        }
                    }
                }
                _ => {}
            },
            1 => {
                // Add a key that the format does not know, or duplicate an array entry.
                match toml_at(doc, parent) {
                    Some(toml::Value::Table(t)) => {
                        t.insert(format!("{key}_x"), interesting_toml(rng));
                    }
                    Some(toml::Value::Array(a)) if !a.is_empty() => {
                        let e = a[rng.below(a.len())].clone();
                        a.push(e);
                    }
                    _ => {}
                }
            }
            _ => {
                if let Some(slot) = toml_at(doc, &path) {
                    *slot = interesting_toml(rng);
                }
            }
        }
    }
}

// ---- The harness -------------------------------------------------------------------------

/// What a loader made of an input.
type Outcome = Result<(), String>;

/// The input under way, for the watchdog: (target, bytes, start in ms since `epoch()`).
static CURRENT: Mutex<Option<(String, Vec<u8>)>> = Mutex::new(None);
static STARTED_MS: AtomicU64 = AtomicU64::new(0);
/// Targets run one at a time, so that the allocator's peak belongs to one input.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn epoch() -> Instant {
    static E: OnceLock<Instant> = OnceLock::new();
    *E.get_or_init(Instant::now)
}

fn findings_dir(target: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("../fuzz-findings")
        .join(target)
}

fn save_finding(target: &str, input: &[u8]) -> PathBuf {
    let dir = findings_dir(target);
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join(format!("{:08x}", crc32(input)));
    let _ = std::fs::write(&path, input);
    path
}

/// Message and place of the last panic, recorded by a quiet panic hook (the inputs that
/// panic are reported together at the end of a target).
static LAST_PANIC: Mutex<Option<String>> = Mutex::new(None);

fn start_watchdog() {
    static W: OnceLock<()> = OnceLock::new();
    W.get_or_init(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if STARTED_MS.load(Relaxed) == 0 {
                return default(info);
            }
            let msg = info
                .payload()
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| info.payload().downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "panic".into());
            let at = info
                .location()
                .map(|l| format!(" at {}:{}", l.file(), l.line()))
                .unwrap_or_default();
            if let Ok(mut p) = LAST_PANIC.lock() {
                *p = Some(format!("{msg}{at}"));
            }
        }));
        std::thread::spawn(|| loop {
            std::thread::sleep(Duration::from_millis(500));
            let started = STARTED_MS.load(Relaxed);
            if started == 0 {
                continue;
            }
            let now = epoch().elapsed().as_millis() as u64;
            if now.saturating_sub(started) > HANG_S * 1000 {
                if let Ok(Some((target, input))) = CURRENT.lock().map(|c| c.clone()) {
                    let path = save_finding(&target, &input);
                    eprintln!(
                        "fuzz target {target}: an input ran longer than {HANG_S} s (hang); \
                         saved to {}",
                        path.display()
                    );
                }
                std::process::exit(3);
            }
        });
    });
}

fn seconds() -> f64 {
    std::env::var("PSRESTIR_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8.0)
}

fn seed() -> u64 {
    std::env::var("PSRESTIR_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1)
}

/// A coarse class of an outcome: "ok", or the refusal message with its digits and file names
/// dropped.
fn class(outcome: &Outcome) -> String {
    match outcome {
        Ok(()) => "ok".into(),
        Err(m) => {
            // Drop the file name; keep the letters and spaces of the first 40 characters.
            let m = m.split_once(": ").map(|(_, r)| r).unwrap_or(m);
            m.chars()
                .take(40)
                .filter(|c| c.is_ascii_alphabetic() || *c == ' ')
                .collect()
        }
    }
}

/// Run `input` through `run` with panics caught and memory measured.
fn execute(
    target: &str,
    input: &[u8],
    run: &dyn Fn(&[u8]) -> Outcome,
) -> (Result<Outcome, String>, usize) {
    if let Ok(mut c) = CURRENT.lock() {
        *c = Some((target.to_string(), input.to_vec()));
    }
    let base = LIVE.load(Relaxed);
    PEAK.store(base, Relaxed);
    STARTED_MS.store(epoch().elapsed().as_millis().max(1) as u64, Relaxed);
    let result = catch_unwind(AssertUnwindSafe(|| run(input))).map_err(|_| {
        LAST_PANIC
            .lock()
            .ok()
            .and_then(|mut p| p.take())
            .unwrap_or_else(|| "panic".into())
    });
    STARTED_MS.store(0, Relaxed);
    (result, PEAK.load(Relaxed).saturating_sub(base))
}

/// A mutation: a new input from an input of the corpus and the whole corpus.
type Mutate = dyn Fn(&mut Rng, &[u8], &[Vec<u8>]) -> Vec<u8>;

struct Target<'a> {
    name: &'a str,
    seeds: Vec<Vec<u8>>,
    mutate: &'a Mutate,
    run: &'a dyn Fn(&[u8]) -> Outcome,
}

/// Replay the regressions, then mutate the corpus for the time budget; fail on any panic,
/// any input over the memory bound, or a seed that is refused.
fn fuzz(t: Target) {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    start_watchdog();
    let seed = seed();
    let budget = Duration::from_secs_f64(seconds());
    let mut rng = Rng(seed);
    let mut failures: Vec<String> = Vec::new();
    // Run one input; a panic or an allocation over the bound is recorded as a failure. Returns
    // the outcome (None after a panic) and the peak allocation.
    let check = |input: &[u8], failures: &mut Vec<String>| -> (Option<Outcome>, usize) {
        let (result, peak) = execute(t.name, input, t.run);
        let outcome = match result {
            Err(msg) => {
                let path = save_finding(t.name, input);
                failures.push(format!("panic `{msg}` on {}", path.display()));
                None
            }
            Ok(outcome) => {
                if peak > MEMORY_BOUND {
                    let path = save_finding(t.name, input);
                    failures.push(format!(
                        "{} MiB allocated (bound {} MiB) on {}",
                        peak >> 20,
                        MEMORY_BOUND >> 20,
                        path.display()
                    ));
                }
                Some(outcome)
            }
        };
        (outcome, peak)
    };

    // Regressions: earlier findings, which must load or be refused without a panic.
    let reg_dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz_regressions")
        .join(t.name);
    let mut regressions = 0;
    if let Ok(entries) = std::fs::read_dir(&reg_dir) {
        let mut files: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
        files.sort();
        for f in files {
            let input = std::fs::read(&f).unwrap();
            check(&input, &mut failures);
            regressions += 1;
        }
    }

    // Seeds must load: otherwise the harness tests nothing but refusals.
    let mut corpus: Vec<Vec<u8>> = Vec::new();
    let mut seen: HashSet<String> = HashSet::new();
    for s in &t.seeds {
        if let (Some(outcome), _) = check(s, &mut failures) {
            assert!(
                outcome.is_ok(),
                "fuzz target {}: seed {} is refused: {outcome:?}",
                t.name,
                corpus.len()
            );
            seen.insert(class(&outcome));
        }
        corpus.push(s.clone());
    }

    let start = Instant::now();
    let (mut runs, mut accepted, mut max_peak) = (0u64, 0u64, 0usize);
    let (mut caught, mut guarded) = (0u64, HashSet::new());
    while start.elapsed() < budget && failures.len() < 5 {
        let parent = rng.pick(&corpus).clone();
        let input = (t.mutate)(&mut rng, &parent, &corpus);
        let (outcome, peak) = check(&input, &mut failures);
        runs += 1;
        max_peak = max_peak.max(peak);
        if let Some(outcome) = outcome {
            accepted += outcome.is_ok() as u64;
            // Panics inside third-party decoders that `catch_panic` turned into errors:
            // not failures, but counted and shown, so that they can be reported upstream.
            if let Err(m) = &outcome {
                if let Some(at) = m.find("failed on this file (") {
                    if guarded.insert(m[at..].chars().take(160).collect::<String>()) {
                        let place = LAST_PANIC.lock().ok().and_then(|mut p| p.take());
                        println!(
                            "fuzz target {}: caught decoder panic: {}",
                            t.name,
                            place.unwrap_or_else(|| m[at..].to_string())
                        );
                    }
                    caught += 1;
                }
            }
            if seen.insert(class(&outcome)) && corpus.len() < 512 {
                corpus.push(input);
            }
        }
    }
    println!(
        "fuzz target {}: seed {seed}, {regressions} regressions replayed, {runs} executions in \
         {:.1} s ({accepted} accepted, {} outcome classes, corpus {}, {caught} decoder panics \
         caught), peak allocation {:.1} MiB, {} failures",
        t.name,
        start.elapsed().as_secs_f64(),
        seen.len(),
        corpus.len(),
        max_peak as f64 / (1 << 20) as f64,
        failures.len()
    );
    assert!(
        failures.is_empty(),
        "fuzz target {} (seed {seed}) found:\n{}",
        t.name,
        failures.join("\n")
    );
}

// ---- Inputs ------------------------------------------------------------------------------

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The scene folders the seeds come from.
fn scene_dirs() -> Vec<PathBuf> {
    let mut v = vec![repo().join("scenes/default")];
    for b in ["vase", "lattice", "dish", "sphere"] {
        v.push(repo().join("scenes/bench").join(b));
    }
    v
}

/// A copy of each scene folder in a temporary directory, where mutated files are written
/// beside the buffers and images they refer to.
fn copies(tmp: &Path) -> Vec<PathBuf> {
    scene_dirs()
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let c = tmp.join(format!("s{i}"));
            std::fs::create_dir_all(&c).unwrap();
            for e in std::fs::read_dir(d).unwrap().flatten() {
                std::fs::copy(e.path(), c.join(e.file_name())).unwrap();
            }
            c
        })
        .collect()
}

/// Which scene folder an input belongs to: its first byte (kept out of the mutation).
fn split_dir(input: &[u8], dirs: &[PathBuf]) -> Option<(PathBuf, Vec<u8>)> {
    let (&k, rest) = input.split_first()?;
    Some((dirs[k as usize % dirs.len()].clone(), rest.to_vec()))
}

fn with_dir(k: usize, bytes: Vec<u8>) -> Vec<u8> {
    let mut v = vec![k as u8];
    v.extend(bytes);
    v
}

/// The JSON and binary chunks of a GLB, when its chunk headers are intact.
fn glb_parts(data: &[u8]) -> Option<(Vec<u8>, Vec<u8>)> {
    let jl = u32::from_le_bytes(data.get(12..16)?.try_into().ok()?) as usize;
    let json = data.get(20..20usize.checked_add(jl)?)?.to_vec();
    let bin = data.get(20 + jl + 8..).unwrap_or(&[]).to_vec();
    Some((json, bin))
}

/// A scene that loaded must pass the renderer's sanity checks (the loader skips or refuses
/// what fails them), then goes through what follows loading on the CPU: the BVH build and
/// the bounds.
fn after_load(s: &scene::Scene) -> Outcome {
    if let Err(e) = s.validate() {
        panic!("the loader accepted a scene that fails validation: {e}");
    }
    let tris: Vec<_> = s.triangles.iter().map(|t| t.p).collect();
    let b = bvh::build(&tris);
    assert_eq!(b.order.len(), tris.len());
    let (c, r) = s.bounding_sphere();
    assert!(c.is_finite() && r.is_finite(), "bounds {c} {r}");
    Ok(())
}

/// Write a scene input as `name` in its folder, load it (and its source parts), and check
/// the result.
fn load_scene_file(input: &[u8], dirs: &[PathBuf], name: &str) -> Outcome {
    let (dir, bytes) = split_dir(input, dirs).ok_or("empty")?;
    let path = dir.join(name);
    std::fs::write(&path, &bytes).unwrap();
    let s = scene::load(&path).map_err(|e| e.to_string())?;
    scene::load_source(&path).map_err(|e| e.to_string())?;
    after_load(&s)
}

fn mutate_json_text(rng: &mut Rng, text: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut out = match serde_json::from_slice::<Value>(text) {
        Ok(mut doc) if rng.chance(0.85) => {
            mutate_json(rng, &mut doc);
            serde_json::to_vec(&doc).unwrap()
        }
        _ => text.to_vec(),
    };
    if rng.chance(0.2) {
        mutate_bytes(rng, &mut out, corpus);
    }
    out
}

// ---- Targets -----------------------------------------------------------------------------

#[test]
fn fuzz_gltf() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = copies(tmp.path());
    let seeds = dirs
        .iter()
        .enumerate()
        .map(|(k, d)| with_dir(k, std::fs::read(d.join("scene.gltf")).unwrap()))
        .collect();
    let run = |input: &[u8]| load_scene_file(input, &dirs, "fuzz.gltf");
    let mutate = |rng: &mut Rng, parent: &[u8], corpus: &[Vec<u8>]| -> Vec<u8> {
        let (&k, text) = parent.split_first().unwrap();
        with_dir(k as usize, mutate_json_text(rng, text, corpus))
    };
    fuzz(Target {
        name: "gltf",
        seeds,
        mutate: &mutate,
        run: &run,
    });
}

#[test]
fn fuzz_glb() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = copies(tmp.path());
    let seeds = dirs
        .iter()
        .enumerate()
        .map(|(k, d)| {
            let mut doc: Value =
                serde_json::from_slice(&std::fs::read(d.join("scene.gltf")).unwrap()).unwrap();
            let bin = std::fs::read(d.join("scene.bin")).unwrap();
            doc["buffers"][0].as_object_mut().unwrap().remove("uri");
            with_dir(k, glb_bytes(&serde_json::to_vec(&doc).unwrap(), &bin))
        })
        .collect();
    let run = |input: &[u8]| load_scene_file(input, &dirs, "fuzz.glb");
    let mutate = |rng: &mut Rng, parent: &[u8], corpus: &[Vec<u8>]| -> Vec<u8> {
        let (&k, data) = parent.split_first().unwrap();
        let out = match glb_parts(data) {
            Some((json, bin)) if rng.chance(0.6) => {
                let json = mutate_json_text(rng, &json, &[]);
                let mut bin = bin;
                if rng.chance(0.2) {
                    mutate_bytes(rng, &mut bin, &[]);
                }
                glb_bytes(&json, &bin)
            }
            _ => {
                let mut d = data.to_vec();
                mutate_bytes(rng, &mut d, corpus);
                d
            }
        };
        with_dir(k as usize, out)
    };
    fuzz(Target {
        name: "glb",
        seeds,
        mutate: &mutate,
        run: &run,
    });
}

#[test]
fn fuzz_task_toml() {
    let tmp = tempfile::tempdir().unwrap();
    let dirs = copies(tmp.path());
    let seeds = dirs
        .iter()
        .enumerate()
        .map(|(k, d)| with_dir(k, std::fs::read(d.join("task.toml")).unwrap()))
        .collect();
    let run = |input: &[u8]| -> Outcome {
        let (dir, bytes) = split_dir(input, &dirs).ok_or("empty")?;
        let path = dir.join("fuzz.toml");
        std::fs::write(&path, &bytes).unwrap();
        let task = Task::load(&path).map_err(|e| e.to_string())?;
        let p = Problem::load(&task).map_err(|e| e.to_string())?;
        after_load(&p.scene)
    };
    let mutate = |rng: &mut Rng, parent: &[u8], corpus: &[Vec<u8>]| -> Vec<u8> {
        let (&k, text) = parent.split_first().unwrap();
        let parsed = std::str::from_utf8(text)
            .ok()
            .and_then(|t| toml::from_str::<toml::Value>(t).ok());
        let mut out = match parsed {
            Some(mut doc) if rng.chance(0.85) => {
                mutate_toml(rng, &mut doc);
                toml::to_string(&doc)
                    .map(String::into_bytes)
                    .unwrap_or_else(|_| text.to_vec())
            }
            _ => text.to_vec(),
        };
        if rng.chance(0.2) {
            mutate_bytes(rng, &mut out, corpus);
        }
        with_dir(k as usize, out)
    };
    fuzz(Target {
        name: "task_toml",
        seeds,
        mutate: &mutate,
        run: &run,
    });
}

/// Small images of several kinds for the image seeds: a gradient with a few flat areas.
fn seed_rgb(w: u32, h: u32) -> Vec<[f32; 3]> {
    (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
            if x < 0.25 {
                [0.2, 0.2, 0.2]
            } else {
                [x, y, 4.0 * x * y]
            }
        })
        .collect()
}

fn decode_texture(input: &[u8]) -> Outcome {
    let img = images::decode_texture(input, Path::new("fuzz"), "image", "fuzz")
        .map_err(|e| e.to_string())?;
    assert_eq!(img.rgba.len(), (img.width * img.height) as usize);
    Ok(())
}

#[test]
fn fuzz_png() {
    let mut seeds: Vec<Vec<u8>> = Vec::new();
    for d in scene_dirs() {
        for e in std::fs::read_dir(d).unwrap().flatten() {
            if e.path().extension().is_some_and(|x| x == "png") {
                seeds.push(std::fs::read(e.path()).unwrap());
            }
        }
    }
    // Other colour types and depths: grey 8 and 16 bit, RGB 8 bit, RGBA 16 bit.
    let rgb = seed_rgb(24, 16);
    let to8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
    let to16 = |v: f32| (v.clamp(0.0, 1.0) * 65535.0) as u16;
    let encode = |img: image::DynamicImage| {
        let mut out = std::io::Cursor::new(Vec::new());
        img.write_to(&mut out, image::ImageFormat::Png).unwrap();
        out.into_inner()
    };
    seeds.push(encode(image::DynamicImage::ImageLuma8(
        image::GrayImage::from_fn(24, 16, |x, y| {
            image::Luma([to8(rgb[(y * 24 + x) as usize][0])])
        }),
    )));
    seeds.push(encode(image::DynamicImage::ImageLuma16(
        image::ImageBuffer::from_fn(24, 16, |x, y| {
            image::Luma([to16(rgb[(y * 24 + x) as usize][1])])
        }),
    )));
    seeds.push(encode(image::DynamicImage::ImageRgb8(
        image::RgbImage::from_fn(24, 16, |x, y| {
            image::Rgb(rgb[(y * 24 + x) as usize].map(to8))
        }),
    )));
    seeds.push(encode(image::DynamicImage::ImageRgba16(
        image::ImageBuffer::from_fn(24, 16, |x, y| {
            let [r, g, b] = rgb[(y * 24 + x) as usize].map(to16);
            image::Rgba([r, g, b, 40000])
        }),
    )));
    let mutate = |rng: &mut Rng, parent: &[u8], corpus: &[Vec<u8>]| -> Vec<u8> {
        let mut d = parent.to_vec();
        mutate_bytes(rng, &mut d, corpus);
        if rng.chance(0.9) {
            fix_png_crcs(&mut d);
        }
        d
    };
    fuzz(Target {
        name: "png",
        seeds,
        mutate: &mutate,
        run: &decode_texture,
    });
}

#[test]
fn fuzz_jpeg() {
    let rgb = seed_rgb(40, 24);
    let to8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0) as u8;
    let img = image::RgbImage::from_fn(40, 24, |x, y| {
        image::Rgb(rgb[(y * 40 + x) as usize].map(to8))
    });
    let mut seeds = Vec::new();
    for quality in [30, 90] {
        let mut out = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, quality)
            .encode_image(&img)
            .unwrap();
        seeds.push(out);
    }
    let grey = image::DynamicImage::ImageRgb8(img).to_luma8();
    let mut out = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, 75)
        .encode_image(&grey)
        .unwrap();
    seeds.push(out);
    fuzz(Target {
        name: "jpeg",
        seeds,
        mutate: &mutated,
        run: &decode_texture,
    });
}

/// An image file read as an environment map and as a target image, then the environment's
/// sampling tables built (what follows on the CPU).
fn env_and_target(path: &Path) -> Outcome {
    let target = psrestir::image_io::load_linear(path);
    let env = EnvMap::load(path).map_err(|e| e.to_string())?;
    let target = target.map_err(|e| e.to_string())?;
    assert_eq!(target.rgb.len(), (target.width * target.height) as usize);
    assert_eq!(env.rgb.len(), (env.width * env.height) as usize);
    let (table, _, _) = env.gpu_table();
    assert!(table.iter().all(|v| v.is_finite()), "non-finite table");
    assert!(env.power(1.0).is_finite());
    Ok(())
}

/// Byte-level mutation only.
fn mutated(rng: &mut Rng, parent: &[u8], corpus: &[Vec<u8>]) -> Vec<u8> {
    let mut d = parent.to_vec();
    mutate_bytes(rng, &mut d, corpus);
    d
}

/// Fuzz files with extension `ext` read as environment maps and target images.
fn fuzz_env_image(ext: &str, seeds: Vec<Vec<u8>>) {
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join(format!("fuzz.{ext}"));
    let run = |input: &[u8]| -> Outcome {
        std::fs::write(&path, input).unwrap();
        env_and_target(&path)
    };
    fuzz(Target {
        name: ext,
        seeds,
        mutate: &mutated,
        run: &run,
    });
}

#[test]
fn fuzz_hdr() {
    let mut seeds = Vec::new();
    for (w, h) in [(32, 16), (9, 5)] {
        let px: Vec<image::Rgb<f32>> = seed_rgb(w, h)
            .into_iter()
            .map(|p| image::Rgb(p.map(|v| v * 20.0)))
            .collect();
        let mut out = Vec::new();
        image::codecs::hdr::HdrEncoder::new(&mut out)
            .encode(&px, w as usize, h as usize)
            .unwrap();
        seeds.push(out);
    }
    fuzz_env_image("hdr", seeds);
}

#[test]
fn fuzz_exr() {
    use exr::prelude::*;
    let tmp = tempfile::tempdir().unwrap();
    let mut seeds = vec![std::fs::read(repo().join("scenes/default/sky.exr")).unwrap()];
    let rgb = seed_rgb(40, 24);
    let compressions = [
        Compression::Uncompressed,
        Compression::RLE,
        Compression::ZIP1,
        Compression::ZIP16,
        Compression::PIZ,
        Compression::PXR24,
        Compression::B44,
        Compression::B44A,
    ];
    for (i, compression) in compressions.into_iter().enumerate() {
        let blocks = if i % 2 == 0 {
            Blocks::ScanLines
        } else {
            Blocks::Tiles(Vec2(16, 16))
        };
        let encoding = Encoding {
            compression,
            blocks,
            line_order: LineOrder::Increasing,
        };
        let half = i >= 5; // B44 and PXR24 compress half floats lossily
        let path = tmp.path().join(format!("seed{i}.exr"));
        let layer = |px: &Vec<[f32; 3]>| {
            let px = px.clone();
            Layer::new(
                (40, 24),
                LayerAttributes::named("rgb"),
                encoding,
                SpecificChannels::rgb(move |Vec2(x, y)| {
                    let p: [f32; 3] = px[y * 40 + x];
                    (
                        f16::from_f32(p[0]),
                        f16::from_f32(p[1]),
                        f16::from_f32(p[2]),
                    )
                }),
            )
        };
        let written = if half {
            Image::from_layer(layer(&rgb)).write().to_file(&path)
        } else {
            let px = rgb.clone();
            Image::from_layer(Layer::new(
                (40, 24),
                LayerAttributes::named("rgb"),
                encoding,
                SpecificChannels::rgb(move |Vec2(x, y)| {
                    let p: [f32; 3] = px[y * 40 + x];
                    (p[0], p[1], p[2])
                }),
            ))
            .write()
            .to_file(&path)
        };
        if written.is_ok() {
            seeds.push(std::fs::read(&path).unwrap());
        }
    }
    assert!(seeds.len() >= 6, "only {} EXR seeds written", seeds.len());
    fuzz_env_image("exr", seeds);
}
