//! The one font of every PNG the tools draw: DejaVu Sans, registered as plotters'
//! "sans-serif".

/// DejaVu Sans (from the `dejavu` crate) as plotters' "sans-serif": no system fonts needed.
pub fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let _ = plotters::style::register_font(
            "sans-serif",
            plotters::style::FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}
