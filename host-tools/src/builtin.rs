//! PLACEHOLDER until the uterus branch lands (replaced wholesale by the merge).
use crate::mesh::Mesh;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    Coarse,
    Medium,
    Fine,
}

impl std::str::FromStr for Level {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "coarse" | "300" => Ok(Level::Coarse),
            "medium" | "2000" => Ok(Level::Medium),
            "fine" | "20000" => Ok(Level::Fine),
            _ => Err(format!("unknown level {s:?} (coarse | medium | fine)")),
        }
    }
}

pub struct ProbeSite {
    pub tube_region: i32,
    pub contact_point: [f64; 3],
    pub push_direction: [f64; 3],
    pub tube_radius_m: f64,
}

pub struct Anatomy {
    pub mesh: Mesh,
    pub cervix_nodes: Vec<u32>,
    pub probe: ProbeSite,
}

pub fn generate(level: Level) -> Anatomy {
    let n = match level {
        Level::Coarse => [10, 2, 2],
        Level::Medium => [40, 4, 4],
        Level::Fine => [80, 8, 8],
    };
    let mut mesh = crate::mesh_io::generate_box([0.1, 0.02, 0.02], n);
    mesh.region_names.insert(1, "body_of_uterus".into());
    let cervix_nodes = (0..mesh.nodes.len() as u32).filter(|&i| mesh.nodes[i as usize][0] < 1e-9).collect();
    Anatomy {
        mesh,
        cervix_nodes,
        probe: ProbeSite { tube_region: 1, contact_point: [0.1, 0.01, 0.02], push_direction: [0.0, 0.0, -1.0], tube_radius_m: 0.01 },
    }
}
