//! The English scene brief a planner reads next to an instruction (paper, Language
//! Instructions: "for each scene in the benchmark, a description of the objects within it is
//! provided").
//!
//! Built from the scene file alone, so it can never disagree with the scene the plan is scored
//! and executed in: the author's free-text `description`, then every zone with the furniture it
//! lies on, then which key objects start in which zone.

use crate::scene::{FurnitureKind, Scene};

impl FurnitureKind {
    /// The noun a person would use.
    pub fn noun(self) -> &'static str {
        match self {
            FurnitureKind::Counter => "counter",
            FurnitureKind::Table => "table",
            FurnitureKind::Shelf => "shelf",
            FurnitureKind::Sink => "sink",
            FurnitureKind::Stove => "stove",
            FurnitureKind::Fridge => "fridge",
            FurnitureKind::Cabinet => "cabinet",
        }
    }
}

impl Scene {
    /// Zones and starting objects in plain English, one sentence per line, deterministic.
    pub fn planner_brief(&self) -> String {
        let zones: Vec<String> = (self.zones.iter())
            .map(|z| {
                let on = self.furniture(&z.furniture).map_or("surface", |f| f.kind.noun());
                format!("the {} zone is on the {on} ({:.2} m high)", z.color, z.height)
            })
            .collect();
        let objects: Vec<String> = (self.zones.iter())
            .filter_map(|z| {
                let here: Vec<String> = (self.key_objects.iter())
                    .filter(|o| o.zone == z.color)
                    .map(|o| format!("the {}", o.name()))
                    .collect();
                let verb = if here.len() == 1 { "is" } else { "are" };
                (!here.is_empty()).then(|| format!("{} {verb} in the {} zone", join(&here), z.color))
            })
            .collect();
        format!(
            "{}\nZones: {}.\nObjects: {}.\n",
            self.description,
            join(&zones),
            join(&objects)
        )
    }
}

/// `a`, `a and b`, `a, b and c`.
fn join(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

#[cfg(test)]
mod tests {
    use crate::catalogue::Catalogue;
    use crate::scene::Scene;

    #[test]
    fn brief_names_every_zone_and_object() {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        for s in Scene::load_all(&dir.join("scenes"), &cat).unwrap() {
            let brief = s.planner_brief();
            for z in &s.zones {
                assert!(
                    brief.contains(&format!("the {} zone is on the", z.color)),
                    "{brief}"
                );
            }
            for o in &s.key_objects {
                assert!(brief.contains(&format!("the {}", o.name())), "{brief}");
            }
        }
        let s = Scene::load(&dir.join("scenes/kitchen_a.toml"), &cat).unwrap();
        assert!(
            s.planner_brief()
                .contains("the red cup and the blue cup are in the red zone")
        );
    }
}
