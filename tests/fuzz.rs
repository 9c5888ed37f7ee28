//! Fuzzed input (proptest): random mutations of the shipped scene and study files (a line
//! deleted, a value replaced by another type or an out-of-range number, a key misspelt, a
//! garbage line inserted, the file truncated) never panic, and every error says where: a key
//! or section (in backticks) or a line of the TOML.

use std::path::Path;

use hvi_run::scene_file::parse_scene;
use hvi_store::spec::Study;
use proptest::prelude::*;

fn repo() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Values of other types and out-of-range numbers a user might type.
const VALUES: &[&str] = &[
    "",
    "\"x\"",
    "-1",
    "0",
    "1e400",
    "nan",
    "inf",
    "[1, 2]",
    "{ a = 1 }",
    "true",
    "\"auto\"",
    "6.7",
    "1e-30",
    "[[]]",
    "\"",
];

/// Lines that are not what a scene or study has.
const GARBAGE: &[&str] = &[
    "[[", "x = ", "= 3", "[scene]", "[axes]", "[bogus]", "a.b = 1", "\u{0}",
];

/// One mutation of `text`, chosen by `op` at line `at` with `pick` choosing the replacement.
fn mutate(text: &str, op: u8, at: usize, pick: usize, cut: usize) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let i = at % lines.len().max(1);
    match op % 5 {
        0 => {
            lines.remove(i);
        }
        1 => {
            if let Some((k, _)) = lines[i].split_once('=') {
                lines[i] = format!("{k}= {}", VALUES[pick % VALUES.len()]);
            }
        }
        2 => {
            if let Some((k, v)) = lines[i].split_once('=') {
                let mut k: Vec<char> = k.trim().chars().collect();
                if !k.is_empty() {
                    let j = pick % k.len();
                    match pick % 3 {
                        0 => {
                            k.remove(j);
                        }
                        1 => k.insert(j, 'x'),
                        _ => {
                            let n = k.len();
                            k.swap(j, (j + 1) % n);
                        }
                    }
                }
                lines[i] = format!("{} ={v}", k.into_iter().collect::<String>());
            }
        }
        3 => lines.insert(i, GARBAGE[pick % GARBAGE.len()].to_string()),
        _ => {
            let joined = lines.join("\n");
            let mut n = cut % (joined.len() + 1);
            while !joined.is_char_boundary(n) {
                n -= 1;
            }
            return joined[..n].to_string();
        }
    }
    lines.join("\n")
}

/// Whether an error message says where the problem is.
fn says_where(msg: &str) -> bool {
    msg.contains('`') || msg.contains("line")
}

proptest! {
    // A fixed seed, so that CI runs the same 2 x 1000 cases every time.
    #![proptest_config(ProptestConfig {
        cases: 1000,
        failure_persistence: None,
        rng_seed: proptest::test_runner::RngSeed::Fixed(20_261_202),
        ..ProptestConfig::default()
    })]

    #[test]
    fn mutated_scene_files_never_panic_and_name_what_is_wrong(
        op in 0u8..5, at in 0usize..200, pick in 0usize..1000, cut in 0usize..5000,
    ) {
        let text = std::fs::read_to_string(repo().join("studies/scenes/default.toml")).expect("scene");
        let text = mutate(&text, op, at, pick, cut);
        let outcome = std::panic::catch_unwind(|| {
            // A small resolution keeps the layout cheap; it is a --set, so it is checked too.
            parse_scene(&text, &["resolution.particles=500".into()])
                .and_then(|spec| spec.build().map(|_| ()).map_err(hvi_run::error::RunError::from))
        });
        let outcome = match outcome {
            Ok(o) => o,
            Err(_) => return Err(TestCaseError::fail(format!("panicked on:\n{text}"))),
        };
        if let Err(e) = outcome {
            let msg = format!("{e:#}");
            prop_assert!(says_where(&msg), "the error does not say where: {msg}\non:\n{text}");
        }
    }

    #[test]
    fn mutated_study_files_never_panic_and_name_what_is_wrong(
        op in 0u8..5, at in 0usize..200, pick in 0usize..1000, cut in 0usize..5000,
    ) {
        let path = repo().join("studies/calibration.toml");
        let text = std::fs::read_to_string(&path).expect("study");
        let text = mutate(&text, op, at, pick, cut);
        let outcome = std::panic::catch_unwind(|| Study::parse(&text, &path));
        let outcome = match outcome {
            Ok(o) => o,
            Err(_) => return Err(TestCaseError::fail(format!("panicked on:\n{text}"))),
        };
        if let Err(e) = outcome {
            let msg = format!("{e:#}");
            prop_assert!(says_where(&msg), "the error does not say where: {msg}\non:\n{text}");
        }
    }
}
