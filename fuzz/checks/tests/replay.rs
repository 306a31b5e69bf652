//! The stable-Rust path of the fuzz targets (no nightly, no libFuzzer): every file in
//! `fuzz/seeds/<target>/` and `fuzz/regressions/<target>/` goes through the target's check,
//! then a bounded run of random mutations of those files (a seeded PRNG: the seed, fixed
//! unless `PE_FUZZ_SEED=<n>` gives another, is printed; `PE_FUZZ_MUTATIONS=<n>` sets the count per
//! target, `PE_FUZZ_SECONDS=<s>` instead runs each target's mutations for `s` seconds). Schedule images are also compiled fresh from the built-in coarse scene, so the
//! image check always starts from images of the current format.

use std::path::{Path, PathBuf};

use pe_fuzz_checks::TARGETS;

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The files of `fuzz/<kind>/<target>/`, sorted (an absent directory has none).
fn inputs(kind: &str, target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = fuzz_dir().join(kind).join(target);
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Vec::new();
    };
    let mut paths: Vec<PathBuf> = entries
        .map(|e| e.expect("readable directory entry").path())
        .filter(|p| p.is_file())
        .collect();
    paths.sort();
    paths
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, bytes)
        })
        .collect()
}

fn check_named(target: &str) -> pe_fuzz_checks::Check {
    TARGETS
        .iter()
        .find(|(n, _)| *n == target)
        .map(|&(_, f)| f)
        .unwrap_or_else(|| panic!("no target {target}"))
}

/// xorshift64*: small, deterministic, enough to pick mutations.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One to eight byte-level mutations of `base` (bit flips, byte sets, interesting values,
/// inserts, deletes, block copies, truncation, splices with `other`).
fn mutate(rng: &mut Rng, base: &[u8], other: &[u8]) -> Vec<u8> {
    let mut d = base.to_vec();
    for _ in 0..1 + rng.below(8) {
        let len = d.len();
        match rng.below(8) {
            0 if len > 0 => {
                let i = rng.below(len);
                d[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                d[i] = rng.next() as u8;
            }
            2 if len > 0 => {
                const VALUES: [u8; 8] = [0, 1, 0x7f, 0x80, 0xff, b'\n', b'-', b'9'];
                let i = rng.below(len);
                d[i] = VALUES[rng.below(VALUES.len())];
            }
            3 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                d.splice(i..i, bytes);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                d.drain(i..i + n);
            }
            5 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                let block = d[i..i + n].to_vec();
                let at = rng.below(len + 1);
                d.splice(at..at, block);
            }
            6 if len > 0 => d.truncate(rng.below(len)),
            7 if !other.is_empty() => {
                let i = rng.below(other.len());
                let n = 1 + rng.below((other.len() - i).min(256));
                let at = rng.below(len + 1);
                d.splice(at..at, other[i..i + n].iter().copied());
            }
            _ => {}
        }
    }
    d
}

fn env_u64(name: &str) -> Option<u64> {
    std::env::var(name).ok().map(|v| {
        v.parse()
            .unwrap_or_else(|_| panic!("{name}={v} is not a number"))
    })
}

thread_local! {
    static LAST_PANIC: std::cell::RefCell<String> = const { std::cell::RefCell::new(String::new()) };
}

/// A quiet panic hook: the message goes to the failing thread's `LAST_PANIC`, printed only
/// when the check fails (the VTK readers catch vtkio's panics, thousands in a run).
fn quiet_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        std::panic::set_hook(Box::new(|info| {
            LAST_PANIC.with(|m| *m.borrow_mut() = info.to_string());
        }))
    });
}

fn last_panic() -> String {
    LAST_PANIC.with(|m| m.borrow().clone())
}

/// Fails the test with `message`, printed first: the quiet hook would swallow the panic's
/// own message, leaving CI a bare `FAILED`.
fn fail(message: String) -> ! {
    eprintln!("{message}");
    panic!("{message}");
}

/// What a target's run went through: mutations run, and the acceptances (parsers that
/// accepted an input, so that its property was checked) among the corpus and the mutations.
struct Tally {
    mutations: u64,
    corpus_accepted: u64,
    mutations_accepted: u64,
}

/// Runs the target's check on every input, then on mutations of them for the budget. A
/// failure names the input, or the seed and mutation number that rebuild it (and saves it).
fn run(target: &str, corpus: &[(PathBuf, Vec<u8>)], budget: Budget, seed: u64) -> Tally {
    let mut tally = Tally {
        mutations: 0,
        corpus_accepted: 0,
        mutations_accepted: 0,
    };
    quiet_panics();
    let check = check_named(target);
    for (path, bytes) in corpus {
        match std::panic::catch_unwind(|| check(bytes)) {
            Ok(n) => tally.corpus_accepted += u64::from(n),
            Err(_) => fail(format!(
                "{target}: {} fails its check: {}",
                path.display(),
                last_panic()
            )),
        }
    }
    let mut rng = Rng(seed | 1);
    let start = std::time::Instant::now();
    let mut k = 0u64;
    while match budget {
        Budget::Mutations(n) => k < n,
        Budget::Seconds(s) => start.elapsed().as_secs_f64() < s,
    } {
        let base = &corpus[rng.below(corpus.len())].1;
        let other = &corpus[rng.below(corpus.len())].1;
        let input = mutate(&mut rng, base, other);
        let outcome = std::panic::catch_unwind(|| check(&input));
        if let Ok(n) = outcome {
            tally.mutations_accepted += u64::from(n);
        } else {
            let out = std::env::temp_dir().join(format!("pe-fuzz-{target}-{seed}-{k}"));
            let _ = std::fs::write(&out, &input);
            fail(format!(
                "{target}: mutation {k} of seed {seed} fails its check: {}\ninput saved to {} \
                 (keep it in fuzz/regressions/{target}/)",
                last_panic(),
                out.display()
            ));
        }
        k += 1;
    }
    tally.mutations = k;
    tally
}

#[derive(Clone, Copy, Debug)]
enum Budget {
    Mutations(u64),
    Seconds(f64),
}

/// The PRNG's seed: `PE_FUZZ_SEED`, else a fixed one (a test run is the same run every
/// time; a longer or different exploration is asked for by seed).
fn seed() -> u64 {
    env_u64("PE_FUZZ_SEED").unwrap_or(0x5EED_F022)
}

fn replay_and_mutate(target: &str) {
    if target == "image_load" {
        // Before reading the seeds, so that a refresh is replayed too.
        let fresh = fresh_images();
        let mut corpus = inputs("seeds", target);
        corpus.extend(inputs("regressions", target));
        corpus.extend(fresh);
        return run_all(target, corpus);
    }
    let mut corpus = inputs("seeds", target);
    let regressions = inputs("regressions", target);
    assert!(
        !corpus.is_empty(),
        "{target}: no seeds in fuzz/seeds/{target}/"
    );
    corpus.extend(regressions);
    run_all(target, corpus);
}

fn run_all(target: &str, corpus: Vec<(PathBuf, Vec<u8>)>) {
    let budget = match (env_u64("PE_FUZZ_SECONDS"), env_u64("PE_FUZZ_MUTATIONS")) {
        (Some(s), _) => Budget::Seconds(s as f64),
        (None, n) => Budget::Mutations(n.unwrap_or(2000)),
    };
    let seed = seed();
    println!(
        "{target}: {} inputs, {budget:?}, PE_FUZZ_SEED={seed}",
        corpus.len()
    );
    let t = run(target, &corpus, budget, seed);
    println!(
        "{target}: {} mutations passed; accepted: {} by the corpus, {} by the mutations",
        t.mutations, t.corpus_accepted, t.mutations_accepted
    );
    // A target that accepts nothing checks nothing but "no panic": its parsers, or its
    // seeds, are broken.
    assert!(
        t.corpus_accepted > 0,
        "{target}: no corpus input was accepted by any parser"
    );
    assert!(
        t.mutations == 0 || t.mutations_accepted > 0,
        "{target}: none of {} mutations was accepted (PE_FUZZ_SEED={seed})",
        t.mutations
    );
}

/// Images of the built-in coarse scene on 1x1x1 and 2x1x1 machines, compiled now through
/// the compiler's API (so they are of this tree's image format), each checked to load.
fn fresh_images() -> Vec<(PathBuf, Vec<u8>)> {
    use host_tools::compile::{compile_images, partition::Machine, plan};
    let mut scene = host_tools::scene::builtin::builtin_scene("coarse").expect("builtin scene");
    scene.solver.steps = Some(10);
    let problem =
        host_tools::problem::Problem::from_scene(&scene, Path::new(".")).expect("builtin problem");
    let mut out = Vec::new();
    for m in ["1x1x1", "2x1x1"] {
        let machine = Machine::parse(m).expect("machine");
        let images =
            compile_images(&problem, &plan(&problem, machine).expect("plan")).expect("images");
        for im in images {
            let name = format!("fresh-{m}-{:?}", im.coords);
            host_tools::compile::decode_image(&im.bytes, None)
                .unwrap_or_else(|e| panic!("{name}: a compiled image decodes: {e}"));
            // `PE_FUZZ_WRITE_IMAGE_SEEDS=1` refreshes the committed seeds (after a format
            // change): `fuzz/seeds/image_load/` is what `cargo fuzz run image_load` starts from.
            if std::env::var_os("PE_FUZZ_WRITE_IMAGE_SEEDS").is_some() {
                let dir = fuzz_dir().join("seeds").join("image_load");
                let file = format!(
                    "coarse-{m}-{}-{}-{}.sched",
                    im.coords[0], im.coords[1], im.coords[2]
                );
                std::fs::write(dir.join(file), &im.bytes).expect("seed written");
            }
            out.push((PathBuf::from(name), im.bytes));
        }
    }
    out
}

#[test]
fn frame_parse() {
    replay_and_mutate("frame_parse");
}

#[test]
fn packet_parse() {
    replay_and_mutate("packet_parse");
}

#[test]
fn stream_decoder() {
    replay_and_mutate("stream_decoder");
}

#[test]
fn payload_parse() {
    replay_and_mutate("payload_parse");
}

#[test]
fn image_load() {
    replay_and_mutate("image_load");
}

#[test]
fn msh_parse() {
    replay_and_mutate("msh_parse");
}

#[test]
fn vtk_parse() {
    replay_and_mutate("vtk_parse");
}

#[test]
fn scene_toml() {
    replay_and_mutate("scene_toml");
}

/// Every target has a test above and a seed directory: a new target cannot be left out.
#[test]
fn every_target_is_replayed() {
    let src = include_str!("replay.rs");
    for (name, _) in TARGETS {
        assert!(
            src.contains(&format!(
                "fn {name}() {{\n    replay_and_mutate(\"{name}\")"
            )),
            "target {name} has no replay test"
        );
        assert!(
            fuzz_dir().join("seeds").join(name).is_dir(),
            "target {name} has no fuzz/seeds/{name}/"
        );
        assert!(
            fuzz_dir()
                .join("fuzz_targets")
                .join(format!("{name}.rs"))
                .is_file(),
            "target {name} has no libFuzzer target"
        );
    }
}
