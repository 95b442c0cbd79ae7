//! Reading scene files from disk: `assets/scenes/<id>.toml`, either the scene itself or a pointer
//! to a USD file with its scale ([`crate::usd_scene`]). Every scene, whatever its source, goes
//! through the same [`Scene::validate`].

use std::path::{Path, PathBuf};

use crate::ContentError;
use crate::catalogue::Catalogue;
use crate::scene::Scene;
use crate::usd_scene::UsdSource;

impl Scene {
    /// Read and validate one scene file against the catalogue. A file holding `usd = "FILE.usda"`
    /// (and optionally `scale`) reads the scene from that USD file instead
    /// ([`crate::usd_scene`]); its id is this file's stem.
    pub fn load(path: &Path, catalogue: &Catalogue) -> Result<Scene, ContentError> {
        let text = std::fs::read_to_string(path).map_err(|source| ContentError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut scene: Scene = match UsdSource::from_toml(path, &text)? {
            Some(source) => source.read(path)?,
            None => toml::from_str(&text).map_err(|e| ContentError::Parse {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?,
        };
        // Mesh files are named relative to the scene file; from here on they are full paths.
        let dir = path.parent().unwrap_or(Path::new("."));
        for f in &mut scene.furniture {
            if let Some(m) = &mut f.mesh {
                m.file = dir.join(&m.file).to_string_lossy().into_owned();
            }
        }
        scene
            .validate(catalogue)
            .map_err(|message| ContentError::Invalid {
                path: path.to_path_buf(),
                message,
            })?;
        Ok(scene)
    }

    /// Every `*.toml` in `dir`, sorted by id.
    pub fn load_all(dir: &Path, catalogue: &Catalogue) -> Result<Vec<Scene>, ContentError> {
        let io = |source| ContentError::Io {
            path: dir.to_path_buf(),
            source,
        };
        let mut paths: Vec<PathBuf> = std::fs::read_dir(dir)
            .map_err(io)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        paths.sort();
        let mut scenes = paths
            .iter()
            .map(|p| Scene::load(p, catalogue))
            .collect::<Result<Vec<_>, _>>()?;
        scenes.sort_by(|a, b| a.id.cmp(&b.id));
        Ok(scenes)
    }
}
