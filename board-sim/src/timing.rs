//! The link timing model of a compiled directory: `host_tools::compile::timing` (the
//! compile report's step model) on the images read from it.

pub use host_tools::compile::timing::{SimTiming, StepTiming};
use host_tools::compile::{decode_image, image_file_name, DecodedImage};

/// Models one step of the machine of `dims` whose images are in `dir`.
pub fn model(dir: &std::path::Path, dims: [usize; 3], t: SimTiming) -> anyhow::Result<StepTiming> {
    let count = dims.iter().product::<usize>();
    let mut imgs: Vec<DecodedImage> = Vec::with_capacity(count);
    for b in 0..count {
        let c = [
            b % dims[0],
            (b / dims[0]) % dims[1],
            b / (dims[0] * dims[1]),
        ];
        let p = dir.join(image_file_name(c));
        let bytes = std::fs::read(&p).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?;
        imgs.push(decode_image(&bytes, None).map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?);
    }
    host_tools::compile::timing::model(&imgs, dims, t)
}
