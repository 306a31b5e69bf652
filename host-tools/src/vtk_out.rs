//! PLACEHOLDER until the mesh-io branch lands (replaced wholesale by the merge).
use std::path::Path;

use crate::mesh::Mesh;

pub struct VtkSeriesWriter;

impl VtkSeriesWriter {
    pub fn new(_dir: &Path, _mesh: &Mesh) -> anyhow::Result<Self> {
        Ok(VtkSeriesWriter)
    }
    pub fn write_frame(&mut self, _time_s: f64, _displacement: &[[f64; 3]]) -> anyhow::Result<()> {
        Ok(())
    }
    pub fn finish(self) -> anyhow::Result<()> {
        Ok(())
    }
}
