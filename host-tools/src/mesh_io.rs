//! PLACEHOLDER until the mesh-io branch lands (replaced wholesale by the merge).
use std::path::Path;

use crate::mesh::Mesh;

#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{0}")]
    Other(String),
}

pub fn load_mesh(path: &Path) -> Result<Mesh, MeshError> {
    Err(MeshError::Other(format!("{}: mesh import not yet available", path.display())))
}

pub fn generate_box(size: [f64; 3], cells: [usize; 3]) -> Mesh {
    let [nx, ny, nz] = cells;
    let id = |i: usize, j: usize, k: usize| (i + (nx + 1) * (j + (ny + 1) * k)) as u32;
    let mut m = Mesh { source: "generated box".into(), ..Default::default() };
    for k in 0..=nz {
        for j in 0..=ny {
            for i in 0..=nx {
                m.nodes.push([
                    size[0] * i as f64 / nx as f64,
                    size[1] * j as f64 / ny as f64,
                    size[2] * k as f64 / nz as f64,
                ]);
                m.node_tags.push(m.nodes.len() as u64);
            }
        }
    }
    for k in 0..nz {
        for j in 0..ny {
            for i in 0..nx {
                m.cells.push([
                    id(i, j, k),
                    id(i + 1, j, k),
                    id(i + 1, j + 1, k),
                    id(i, j + 1, k),
                    id(i, j, k + 1),
                    id(i + 1, j, k + 1),
                    id(i + 1, j + 1, k + 1),
                    id(i, j + 1, k + 1),
                ]);
                m.cell_regions.push(1);
            }
        }
    }
    m.region_names.insert(1, "box".into());
    m
}
