//! The English scene brief a planner reads next to an instruction (paper, Language
//! Instructions: "for each scene in the benchmark, a description of the objects within it is
//! provided").
//!
//! Built from the scene file alone, so it can never disagree with the scene the plan is scored
//! and executed in: the author's free-text `description`, then every zone with the furniture it
//! lies on and the referring expressions instructions may use for it instead of its colour
//! (`Zone::names`, so a planner can ground "the dining table" to the colour its plan must say),
//! then which key objects start in which zone.

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
                let zone = format!("the {} zone is on the {on} ({:.2} m high)", z.color, z.height);
                match z.names.as_slice() {
                    [] => zone,
                    names => format!("{zone}, also called {}", join_or(names)),
                }
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
        // Zones are separated by semicolons: a zone's own clause may hold commas.
        format!(
            "{}\nZones: {}.\nObjects: {}.\n",
            self.description,
            zones.join("; "),
            join(&objects)
        )
    }
}

/// `a`, `a and b`, `a, b and c`.
fn join(items: &[String]) -> String {
    join_with(items, "and")
}

/// `a`, `a or b`, `a, b or c`.
fn join_or(items: &[String]) -> String {
    join_with(items, "or")
}

fn join_with(items: &[String], word: &str) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} {word} {last}", init.join(", ")),
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
        assert_eq!(s.planner_brief(), s.planner_brief(), "deterministic");
        assert!(
            s.planner_brief()
                .contains("the red cup and the blue cup are in the red zone")
        );
    }

    /// Every referring expression of a zone is in the brief, tied to that zone's colour.
    #[test]
    fn brief_grounds_furniture_names_to_colours() {
        let dir = crate::assets::assets_dir();
        let cat = Catalogue::load(&dir.join("objects.toml")).unwrap();
        for s in Scene::load_all(&dir.join("scenes"), &cat).unwrap() {
            let brief = s.planner_brief();
            let zones_line = brief.lines().find(|l| l.starts_with("Zones: ")).unwrap();
            for z in s.zones.iter().filter(|z| !z.names.is_empty()) {
                let from = zones_line.find(&format!("the {} zone is on", z.color)).unwrap();
                let expected = match z.names.as_slice() {
                    [one] => format!("also called {one}"),
                    [init @ .., last] => format!("also called {} or {last}", init.join(", ")),
                    [] => unreachable!(),
                };
                assert!(zones_line[from..].contains(&expected), "{brief}");
            }
        }
        let mut s = Scene::load(&dir.join("scenes/kitchen_a.toml"), &cat).unwrap();
        let blue = s.zones.iter_mut().find(|z| z.color == "blue").unwrap();
        blue.names = vec!["the left end of the back counter".into()];
        assert!(s.planner_brief().contains(
            "the blue zone is on the counter (0.90 m high), also called the left end of the back counter"
        ));
        s.zones.iter_mut().for_each(|z| z.names.clear());
        assert!(!s.planner_brief().contains("also called"));
    }
}
