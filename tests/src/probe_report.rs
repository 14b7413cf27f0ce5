//! Reading `ecmxfd probe`'s report: one line per step (`N. name  ok|WARN|
//! FAIL|skip  what`), the cause and fix indented under a failed step.

/// The line of step `n` and the lines under it up to the next step.
pub fn step(text: &str, n: usize) -> String {
    let start = text.find(&format!("\n{n}. ")).unwrap_or_else(|| panic!("no step {n} in:\n{text}")) + 1;
    let rest = &text[start..];
    let end = rest.find(&format!("\n{}. ", n + 1)).map_or(rest.len(), |e| e + 1);
    rest[..end].to_string()
}

/// Step `n` failed saying each of `words`, the steps before it passed, the
/// ones after were skipped, and the probe exited 1.
#[track_caller]
pub fn assert_fails_at(text: &str, n: usize, code: i32, words: &[&str]) {
    assert_eq!(code, 1, "{text}");
    let s = step(text, n);
    assert!(s.contains(" FAIL ") && s.contains("cause: ") && s.contains("fix: "), "step {n}:\n{text}");
    for w in words {
        assert!(s.contains(w), "step {n} does not say {w:?}:\n{text}");
    }
    for before in 1..n {
        assert!(step(text, before).contains(" ok "), "step {before} before the failure:\n{text}");
    }
    for after in n + 1..=7 {
        assert!(step(text, after).contains(" skip "), "step {after} after the failure:\n{text}");
    }
    assert!(text.contains(&format!("step {n} failed")), "{text}");
}

/// Every step passed and the probe exited 0.
#[track_caller]
pub fn assert_passes(code: i32, text: &str) {
    assert_eq!(code, 0, "{text}");
    for n in 1..=7 {
        assert!(step(text, n).contains(" ok "), "step {n}:\n{text}");
    }
    assert!(text.contains("all 7 steps passed"), "{text}");
}
