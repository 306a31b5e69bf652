//! The firmware's measured cost: executed instructions per element, node and contact node
//! of a step (the compile report's capacity, board-sim's timing model, the trade-off
//! study), and the one formula of a step's instructions ([`StepCost`]).

use super::BoardProfile;
use crate::physics::ElementKind;

/// Executed instructions of the board firmware per element and per node in one step,
/// measured under QEMU (mps2-an500, Cortex-M7 with FPU, `-C target-cpu=cortex-m7`) with an
/// exact instruction counter by `scripts/board-cost.sh`: the general kernel and the node
/// update on the built-in coarse scene (351 elements, all distorted, 731 nodes, 1x1x1) after
/// 900 steps, the probe pressing the tube; the cuboid kernel on a 10x5x5 box sagging under
/// gravity, the parallelepiped kernel on the same box turned by 30° about x. The node update includes the step's contact, graphics and external-force
/// work. Instructions, not cycles: capacity figures take one instruction per cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirmwareCost {
    pub precision: crate::image::Precision,
    pub integration: crate::image::Integration,
    /// One general element's internal forces (the physics kernel alone).
    pub kernel_per_element: u32,
    /// Per general element of the element loop: kernel, gathering displacements,
    /// scattering forces.
    pub per_element_step: u32,
    /// The same for a parallelepiped ([`crate::physics::HexBox`]; 0 for full
    /// integration, which has no such kernel).
    pub box_kernel_per_element: u32,
    pub box_per_element_step: u32,
    /// The same for an axis-aligned cuboid ([`crate::physics::HexCuboid`]; 0 for full
    /// integration).
    pub cuboid_kernel_per_element: u32,
    pub cuboid_per_element_step: u32,
    /// Per node and step: external forces, central-difference update, checks (a node
    /// without contact: measured on the regular box).
    pub per_node_update: u32,
    /// Per contact-surface node and step, on a board that evaluates the contact of the
    /// whole table: a step's contact evaluation (positions, travel check, tool and pair
    /// tests) over the table's nodes, measured on its own between marks on the built-in
    /// scene (one board owning every contact node, in the board-cost state). Not in it: a
    /// check step's candidate search (once per check interval: [`Self::per_search_test`])
    /// and the contact-node packets a board of a partition sends and receives.
    pub per_contact_node: u32,
    /// Per node-face test of a check step's candidate search
    /// ([`crate::physics::contact::search_tests`]): a check step's contact evaluation less
    /// a step's, over the search's tests, measured on the same state (the search and
    /// keeping the groups that give the board's nodes a force). It carries the search's
    /// work per face (the boxes) and per candidate (the sort, the groups kept) too: on
    /// the built-in coarse scene 186 040 against a step's 31 367 instructions for 5 184
    /// tests, the box test itself some 14 of the 30 (`scripts/firmware-profile.sh`).
    pub per_search_test: u32,
    /// A whole step divided by the elements, on the measured scene.
    pub step_per_element: u32,
}

impl FirmwareCost {
    /// Instructions per element-step (kernel, gather, scatter) of kind `k`: the measured
    /// figure of this row's precision; 0 for a kind of the other integration (this row
    /// measured none).
    pub fn element_step(&self, k: ElementKind) -> u32 {
        match k {
            _ if k.integration() != self.integration => 0,
            ElementKind::HexReduced | ElementKind::HexFull => self.per_element_step,
            ElementKind::HexBox => self.box_per_element_step,
            ElementKind::HexCuboid => self.cuboid_per_element_step,
        }
    }

    /// Its figures as a [`StepCost`] (the one formula of a step's instructions), per
    /// element table ([`ElementKind::table`] order).
    pub fn step_cost(&self) -> StepCost {
        StepCost {
            per_element: core::array::from_fn(|t| self.table_step(t) as f64),
            per_node_update: self.per_node_update as f64,
            per_contact_node: self.per_contact_node as f64,
        }
    }

    /// [`Self::element_step`] of the kind element table `t` holds in this row's
    /// integration (0 where the table stays empty).
    fn table_step(&self, t: usize) -> u32 {
        ElementKind::in_table(self.integration, t).map_or(0, |k| self.element_step(k))
    }

    /// Instructions of one step of a board holding `per_table[t]` elements in each element
    /// table ([`ElementKind::table`] order) and `nodes` nodes, charged for `contact_nodes`
    /// contact nodes ([`Self::charged_contact_nodes`]; no exchange): [`StepCost::step`].
    pub fn step_instructions(
        &self,
        per_table: [usize; ElementKind::TABLES],
        nodes: usize,
        contact_nodes: usize,
    ) -> f64 {
        self.step_cost().step(
            per_table.map(|n| n as f64),
            nodes as f64,
            contact_nodes as f64,
        )
    }

    /// The contact-surface nodes a board's step is charged [`Self::per_contact_node`] for
    /// (the one rule of the compile report and board-sim's timing model), from the
    /// contact table's length (every board that owns a contact node holds the whole table)
    /// and the contact nodes the board owns:
    /// - a board that owns a contact node evaluates the contact problem of the whole
    ///   table: its positions and, at each check, the candidate groups that give one of
    ///   its nodes a force, which on a small contact surface are most of them (measured by
    ///   `scripts/contact-cost.sh`: see docs/measurements/board-cost.md);
    /// - a board that owns none has no contact tables and no contact operation in its step
    ///   (every result would be zero), and is charged nothing.
    pub fn charged_contact_nodes(table_nodes: usize, owned_contact_nodes: usize) -> usize {
        if owned_contact_nodes > 0 {
            table_nodes
        } else {
            0
        }
    }

    /// Per element of a mix with fractions `mix[t]` in each element table
    /// ([`ElementKind::table`] order): [`StepCost::elements`] of the mix.
    pub fn per_element_of_mix(&self, mix: [f64; ElementKind::TABLES]) -> f64 {
        self.step_cost().elements(mix)
    }

    /// Elements one board of `profile` computes at `rate_hz` steps per second, with
    /// `nodes_per_element` nodes (`contact_per_element` contact nodes) per element and
    /// fractions `mix` in each element table, taking one instruction per cycle.
    pub fn elements_per_board(
        &self,
        profile: &BoardProfile,
        rate_hz: f64,
        nodes_per_element: f64,
        contact_per_element: f64,
        mix: [f64; ElementKind::TABLES],
    ) -> f64 {
        profile.clock_hz as f64
            / rate_hz
            / self
                .step_cost()
                .step(mix, nodes_per_element, contact_per_element)
    }
}

/// What a board's step costs in instructions: per element of each kernel ([`Kernel`]
/// order), per node update and per contact node charged
/// ([`FirmwareCost::charged_contact_nodes`]). From the measured table
/// ([`FirmwareCost::step_cost`]) or a timing model's figures; the one formula of a step's
/// instructions (the compile report's capacity, the step model's batches and node update,
/// the trade-off study's board real-time factor):
///
/// `I = Σ_k n_k · e_k + nodes · u + contact_nodes · c`
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCost {
    pub per_element: [f64; ElementKind::TABLES],
    pub per_node_update: f64,
    pub per_contact_node: f64,
}

impl StepCost {
    /// The element loop's instructions for `elements[k]` elements of each kernel:
    /// `Σ_k n_k · e_k`.
    pub fn elements(&self, elements: [f64; ElementKind::TABLES]) -> f64 {
        (0..ElementKind::TABLES)
            .map(|t| elements[t] * self.per_element[t])
            .sum()
    }

    /// The node update's instructions: `nodes · u + contact_nodes · c`.
    pub fn update(&self, nodes: f64, contact_nodes: f64) -> f64 {
        nodes * self.per_node_update + contact_nodes * self.per_contact_node
    }

    /// A whole step's (no exchange): [`Self::elements`] and then the terms of
    /// [`Self::update`], added in this order.
    pub fn step(
        &self,
        elements: [f64; ElementKind::TABLES],
        nodes: f64,
        contact_nodes: f64,
    ) -> f64 {
        self.elements(elements)
            + nodes * self.per_node_update
            + contact_nodes * self.per_contact_node
    }
}

/// The measured table (scripts/board-cost.sh, run by CI: a test fails when a figure here is
/// more than 3% off the measurement; update it from that script's output).
pub const MEASURED_COST: [FirmwareCost; 4] = {
    use crate::image::{Integration::*, Precision::*};
    [
        FirmwareCost {
            precision: F64,
            integration: Reduced,
            kernel_per_element: 1126,
            per_element_step: 1145,
            box_kernel_per_element: 797,
            box_per_element_step: 905,
            cuboid_kernel_per_element: 579,
            cuboid_per_element_step: 669,
            per_node_update: 79,
            per_contact_node: 275,
            per_search_test: 29,
            step_per_element: 1370,
        },
        FirmwareCost {
            precision: F64,
            integration: Full,
            kernel_per_element: 4038,
            per_element_step: 4110,
            box_kernel_per_element: 0,
            box_per_element_step: 0,
            cuboid_kernel_per_element: 0,
            cuboid_per_element_step: 0,
            per_node_update: 79,
            per_contact_node: 274,
            per_search_test: 29,
            step_per_element: 4328,
        },
        FirmwareCost {
            precision: F32,
            integration: Reduced,
            kernel_per_element: 877,
            per_element_step: 950,
            box_kernel_per_element: 623,
            box_per_element_step: 727,
            cuboid_kernel_per_element: 444,
            cuboid_per_element_step: 556,
            per_node_update: 88,
            per_contact_node: 268,
            per_search_test: 29,
            step_per_element: 1191,
        },
        FirmwareCost {
            precision: F32,
            integration: Full,
            kernel_per_element: 3239,
            per_element_step: 3350,
            box_kernel_per_element: 0,
            box_per_element_step: 0,
            cuboid_kernel_per_element: 0,
            cuboid_per_element_step: 0,
            per_node_update: 88,
            per_contact_node: 268,
            per_search_test: 29,
            step_per_element: 3585,
        },
    ]
};

/// The measured cost of a variant.
pub fn measured_cost(
    precision: crate::image::Precision,
    integration: crate::image::Integration,
) -> FirmwareCost {
    let mut c = MEASURED_COST[0];
    for m in MEASURED_COST {
        if m.precision == precision && m.integration == integration {
            c = m;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A step's instructions by hand (957, 668 and 539 per general, parallelepiped and
    /// cuboid element, 79 per node, 275 per contact node): 10 + 2 + 1 elements, 20 nodes
    /// and 5 contact nodes are 9570 + 1336 + 539 + 1580 + 1375 = 14 400; the step is its
    /// element loop and its update.
    #[test]
    fn a_steps_instructions_are_its_elements_and_its_update() {
        let c = FirmwareCost {
            per_element_step: 957,
            box_per_element_step: 668,
            cuboid_per_element_step: 539,
            per_node_update: 79,
            per_contact_node: 275,
            ..MEASURED_COST[0]
        };
        assert_eq!(c.step_instructions([10, 2, 1], 20, 5), 14_400.0);
        let s = c.step_cost();
        assert_eq!(s.elements([10.0, 2.0, 1.0]), 11_445.0);
        assert_eq!(s.update(20.0, 5.0), 2_955.0);
        assert_eq!(s.step([10.0, 2.0, 1.0], 20.0, 5.0), 14_400.0);
    }
}
