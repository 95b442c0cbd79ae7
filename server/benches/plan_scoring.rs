//! Parse + validate + score one 563-line plan file (target ≤ 5 ms, docs/measured/performance.md).
//!
//! The dataset is synthetic (563 instructions of 4 to 8 canonical steps, the generator's
//! shape) so the benchmark does not depend on the committed files; the submitted file gets
//! every third step wrong so scoring compares strings that differ.
//!
//! Run: `cargo bench -p kitchen-r-server --bench plan_scoring`

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use kitchen_r_core::dataset::{Instruction, Split};
use kitchen_r_server::PlanLimits;
use kitchen_r_server::plans::{self, IdIndex};

const ZONES: [&str; 4] = ["red", "green", "blue", "yellow"];
const OBJECTS: [&str; 5] = ["apple", "bowl", "red cup", "fork", "plate"];

fn instruction(i: usize) -> Instruction {
    let steps = 4 + i % 5;
    let plan = (0..steps)
        .map(|j| match j % 4 {
            0 | 2 => format!("move to the {} zone", ZONES[(i + j) % 4]),
            1 => format!("pick the {}", OBJECTS[i % 5]),
            _ => format!("place the {}", OBJECTS[i % 5]),
        })
        .collect();
    Instruction {
        id: format!("dev-{i:04}"),
        scene: "kitchen_a".into(),
        instruction: format!("bring the {} to the {} zone", OBJECTS[i % 5], ZONES[i % 4]),
        plan,
        template: format!("t{:02}", i % 58),
        place_targets: vec![],
    }
}

fn plan_file(dataset: &[Instruction]) -> Vec<u8> {
    let mut out = Vec::new();
    for inst in dataset {
        let plan: Vec<String> = inst
            .plan
            .iter()
            .enumerate()
            .map(|(j, s)| {
                if j % 3 == 2 {
                    "pick the fork".to_string()
                } else {
                    s.clone()
                }
            })
            .collect();
        serde_json::to_writer(&mut out, &serde_json::json!({ "id": inst.id, "plan": plan })).unwrap();
        out.push(b'\n');
    }
    out
}

fn bench(c: &mut Criterion) {
    let dataset: Vec<Instruction> = (0..563).map(instruction).collect();
    let index = IdIndex::new(&dataset, &[]);
    let body = plan_file(&dataset);
    let limits = PlanLimits::default();
    c.bench_function("parse_validate_score_563_lines", |b| {
        b.iter(|| {
            let file = plans::parse(black_box(&body), Split::Dev, dataset.len(), &index, &limits).unwrap();
            black_box(plans::score(&file, &dataset))
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
