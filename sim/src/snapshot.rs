//! Snapshot, restore and a hash of the full dynamic state.
//!
//! A snapshot clones every physics set (bodies, colliders, joints, broad and narrow phase with
//! their warm-start data, islands) plus the controller state, so restoring and stepping gives the
//! same bits as never having left. The pipeline and CCD solver are workspaces and are recreated.

use rapier3d::prelude::*;

use crate::sim::{Dynamic, Sim};

/// The whole mutable state of a [`Sim`] for the episode it was taken in.
#[derive(Clone)]
pub struct Snapshot {
    episode: String,
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    integration_parameters: IntegrationParameters,
    dynamic: Dynamic,
}

impl std::fmt::Debug for Snapshot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Snapshot")
            .field("episode", &self.episode)
            .field("substeps", &self.dynamic.substeps)
            .finish()
    }
}

impl Sim {
    pub fn snapshot(&self) -> Snapshot {
        let w = &self.world;
        Snapshot {
            episode: self.episode.id.clone(),
            islands: w.islands.clone(),
            broad_phase: w.broad_phase.clone(),
            narrow_phase: w.narrow_phase.clone(),
            bodies: w.bodies.clone(),
            colliders: w.colliders.clone(),
            impulse_joints: w.impulse_joints.clone(),
            multibody_joints: w.multibody_joints.clone(),
            integration_parameters: w.integration_parameters,
            dynamic: self.dynamic.clone(),
        }
    }

    /// Restore a snapshot taken in the current episode (after `reset` to another episode the
    /// handles would not match, so that is refused).
    pub fn restore(&mut self, s: &Snapshot) -> Result<(), crate::SimError> {
        if s.episode != self.episode.id {
            return Err(crate::SimError::Episode(format!(
                "snapshot is from episode {:?}, the sim runs {:?}",
                s.episode, self.episode.id
            )));
        }
        let w = &mut self.world;
        w.islands = s.islands.clone();
        w.broad_phase = s.broad_phase.clone();
        w.narrow_phase = s.narrow_phase.clone();
        w.bodies = s.bodies.clone();
        w.colliders = s.colliders.clone();
        w.impulse_joints = s.impulse_joints.clone();
        w.multibody_joints = s.multibody_joints.clone();
        w.integration_parameters = s.integration_parameters;
        w.physics_pipeline = PhysicsPipeline::new();
        w.ccd_solver = CCDSolver::new();
        self.dynamic = s.dynamic.clone();
        Ok(())
    }

    /// FNV-1a over the bits of every body's pose and velocity and the controller state.
    pub fn state_hash(&self) -> u64 {
        let mut h = Fnv(crate::seeds::FNV_OFFSET);
        for (_, b) in self.world.bodies.iter() {
            let p = b.position();
            let (t, r, lv, av) = (p.translation, p.rotation, b.linvel(), b.angvel());
            for v in [
                t.x, t.y, t.z, r.x, r.y, r.z, r.w, lv.x, lv.y, lv.z, av.x, av.y, av.z,
            ] {
                h.u64(u64::from(v.to_bits()));
            }
        }
        let d = &self.dynamic;
        // The arm's own joints only: the unused slots of a six-joint arm's vectors stay out.
        let dof = self.robot.arm.dof;
        for v in d
            .robot
            .arm
            .q
            .iter()
            .take(dof)
            .chain(d.robot.arm.qd.iter().take(dof))
        {
            h.u64(v.to_bits());
        }
        for v in [d.robot.v, d.robot.omega, d.robot.opening] {
            h.u64(v.to_bits());
        }
        h.u64(d.substeps);
        h.u64(d.held.map_or(u64::MAX, |x| x.object as u64));
        h.0
    }
}

struct Fnv(u64);

impl Fnv {
    fn u64(&mut self, v: u64) {
        self.0 = crate::seeds::fnv1a(self.0, &v.to_le_bytes());
    }
}
