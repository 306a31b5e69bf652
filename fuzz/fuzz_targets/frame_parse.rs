//! libFuzzer target: the check is [`pe_fuzz_checks::frame_parse`] (shared with the stable replay
//! test in `fuzz/checks/tests/replay.rs`).
#![no_main]

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _accepted = pe_fuzz_checks::frame_parse(data);
});
