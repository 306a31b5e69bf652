//! The link timing model of a compiled directory: `host_tools::compile::timing` (the
//! compile report's step model) on the images read from it.

pub use host_tools::compile::timing::{SimTiming, StepTiming};
use host_tools::compile::{decode_image, image_file_name, DecodedImage};
use link_proto::Machine;

/// Models one step of the machine of `dims` whose images are in `dir`.
pub fn model(dir: &std::path::Path, dims: [usize; 3], t: SimTiming) -> anyhow::Result<StepTiming> {
    let machine =
        Machine::new(dims).ok_or_else(|| anyhow::anyhow!("{dims:?}: 1..16 boards per axis"))?;
    let mut imgs: Vec<DecodedImage> = Vec::with_capacity(machine.count());
    for b in 0..machine.count() {
        let p = dir.join(image_file_name(machine.coords(b)));
        let bytes = std::fs::read(&p).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
        imgs.push(decode_image(&bytes, None).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?);
    }
    host_tools::compile::timing::model(&imgs, dims, t)
}
