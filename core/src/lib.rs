//! Kitchen-R benchmark content shared by every other crate: the scene and object-catalogue
//! schemas (read from `assets/`), the navigability rules of scene layouts, canonical plan steps,
//! the instruction templates and deterministic dataset generator, top-down scene images, and the
//! metrics (EM, MSE, SR, M, P).
//!
//! This crate is pure data and arithmetic. It must not do physics, camera rendering, networking
//! or storage (the top-down image is a flat map painted from the scene file, not a camera view):
//! `sim` steps the physics, `server` stores and serves, and both read content from here so that a
//! scene file or a plan string means the same thing everywhere.

pub mod assets;
pub mod audit;
pub mod catalogue;
pub mod catalogue_mjcf;
pub mod dataset;
pub mod describe;
pub mod error;
pub mod grasp_mode;
pub mod interval;
pub mod layout;
pub mod metrics;
pub mod observations;
pub mod plan;
pub mod reach;
pub mod robot;
pub mod scene;
mod scene_load;
pub mod scoring;
pub mod topdown;
pub mod usd_scene;
pub mod usda;

pub use error::ContentError;
pub use grasp_mode::GraspMode;

#[cfg(test)]
mod asset_tests {
    use crate::catalogue::Catalogue;
    use crate::scene::Scene;

    /// Every committed scene must load and validate against the committed catalogue.
    #[test]
    fn committed_scenes_validate() {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        let scenes = Scene::load_all(&dir.join("scenes"), &cat).unwrap();
        assert!(!scenes.is_empty());
        assert!(scenes.len() >= 3, "the benchmark ships at least three kitchens");
        for s in &scenes {
            s.check_layout().unwrap_or_else(|e| panic!("{}: {e}", s.id));
            s.check_contents(&cat).unwrap_or_else(|e| panic!("{}: {e}", s.id));
            for o in &s.key_objects {
                let m = cat.model(&o.model).unwrap();
                assert!(s.key_object_start(o, m.shape.half_height()).is_some());
            }
        }
    }
}
