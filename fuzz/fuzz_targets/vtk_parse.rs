//! libFuzzer target: the check is [`pe_fuzz_checks::vtk_parse`] (shared with the stable replay
//! test in `fuzz/checks/tests/replay.rs`).
//!
//! libfuzzer-sys's panic hook aborts on every panic, even one caught: the VTK readers catch
//! vtkio's own panics (`vtkio_guarded`) and turn them into errors, so this target restores
//! the default hook. A panic that escapes the check still aborts (libfuzzer-sys's
//! `catch_unwind` around each input), so every real crash is still found.
#![no_main]

libfuzzer_sys::fuzz_target!(
    init: {
        let _ = std::panic::take_hook();
    },
    |data: &[u8]| {
        let _accepted = pe_fuzz_checks::vtk_parse(data);
    }
);
