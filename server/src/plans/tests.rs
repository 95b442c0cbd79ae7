use proptest::prelude::*;

use super::*;

fn inst(id: &str, plan: &[&str]) -> Instruction {
    Instruction {
        id: id.into(),
        scene: "kitchen_a".into(),
        instruction: "do it".into(),
        plan: plan.iter().map(|s| s.to_string()).collect(),
        template: "t".into(),
        place_targets: vec![],
    }
}

struct Fixture {
    dev: Vec<Instruction>,
    index: IdIndex,
}

fn fixture() -> Fixture {
    let dev = vec![
        inst(
            "dev-0001",
            &[
                "move to the blue zone",
                "pick the bowl",
                "move to the red zone",
                "place the bowl",
            ],
        ),
        inst(
            "dev-0002",
            &[
                "move to the green zone",
                "pick the cup",
                "move to the red zone",
                "place the cup",
            ],
        ),
    ];
    let test = vec![inst("test-0001", &["move to the blue zone", "pick the cup"])];
    let index = IdIndex::new(&dev, &test);
    Fixture { dev, index }
}

fn parse_dev(f: &Fixture, body: &str) -> Result<PlanFile, PlanFileError> {
    parse(
        body.as_bytes(),
        Split::Dev,
        f.dev.len(),
        &f.index,
        &PlanLimits::default(),
    )
}

#[test]
fn ground_truth_scores_one_and_extra_keys_are_ignored() {
    let f = fixture();
    let body: String = f
        .dev
        .iter()
        .map(|i| serde_json::to_string(i).unwrap() + "\n")
        .collect();
    let s = score(&parse_dev(&f, &body).unwrap(), &f.dev);
    assert_eq!(s.em, 1.0);
    assert_eq!(s.missing, 0);
    assert!(warnings(&s).is_empty());
}

#[test]
fn missing_instructions_score_zero_and_warn() {
    let f = fixture();
    let body = r#"{"id": "dev-0002", "plan": ["move to the green zone", "pick the cup", "x"]}"#;
    let s = score(&parse_dev(&f, body).unwrap(), &f.dev);
    // dev-0001 missing: 0; dev-0002: 2/4
    assert_eq!(s.em, 0.25);
    assert_eq!(s.missing, 1);
    assert!(warnings(&s)[0].starts_with("1 of 2 instructions"));
    assert!(!s.instructions[0].present);
}

#[test]
fn every_bad_line_is_named_with_its_line_number() {
    let f = fixture();
    let ok = r#"{"id": "dev-0001", "plan": []}"#;
    let cases: Vec<(String, &str, usize)> = vec![
        (format!("{ok}\n{{not json"), "not_json", 2),
        (format!("\n{ok}\n[1, 2]"), "not_an_object", 3),
        (r#"{"plan": []}"#.into(), "missing_id", 1),
        (r#"{"id": 7, "plan": []}"#.into(), "missing_id", 1),
        (r#"{"id": "dev-9999", "plan": []}"#.into(), "unknown_id", 1),
        (r#"{"id": "test-0001", "plan": []}"#.into(), "wrong_split", 1),
        (format!("{ok}\n{ok}"), "duplicate_id", 2),
        (
            r#"{"id": "dev-0001", "plan": "pick the cup"}"#.into(),
            "plan_not_a_list",
            1,
        ),
        (r#"{"id": "dev-0001"}"#.into(), "plan_not_a_list", 1),
        (
            r#"{"id": "dev-0001", "plan": ["a", 3]}"#.into(),
            "step_not_a_string",
            1,
        ),
        (
            format!(r#"{{"id": "dev-0001", "plan": ["{}"]}}"#, "a".repeat(201)),
            "step_too_long",
            1,
        ),
        (
            format!(
                r#"{{"id": "dev-0001", "plan": [{}]}}"#,
                vec!["\"a\""; 65].join(",")
            ),
            "too_many_steps",
            1,
        ),
    ];
    for (body, code, line) in cases {
        let e = parse_dev(&f, &body).unwrap_err();
        assert_eq!((e.code(), e.line()), (code, Some(line)), "{body}: {e}");
    }
    let bad_utf8 = [ok.as_bytes(), b"\n\xff\xfe"].concat();
    let e = parse(&bad_utf8, Split::Dev, 2, &f.index, &PlanLimits::default()).unwrap_err();
    assert_eq!(e, PlanFileError::NotUtf8 { line: 2 });
}

#[test]
fn a_byte_order_mark_at_the_start_is_skipped_and_lines_keep_their_numbers() {
    let f = fixture();
    let gt: String = f
        .dev
        .iter()
        .map(|i| serde_json::to_string(i).unwrap() + "\r\n")
        .collect();
    let with_bom = format!("\u{feff}{gt}");
    let file = parse_dev(&f, &with_bom).unwrap();
    assert_eq!(score(&file, &f.dev).em, 1.0);
    // Errors after it still name the right line.
    let e = parse_dev(&f, &format!("\u{feff}{gt}{{oops")).unwrap_err();
    assert_eq!((e.code(), e.line()), ("not_json", Some(3)), "{e}");
    // A mark only counts at the very start: elsewhere it is not JSON whitespace.
    let e = parse_dev(&f, &format!("{gt}\u{feff}{{}}")).unwrap_err();
    assert_eq!((e.code(), e.line()), ("not_json", Some(3)), "{e}");
    // A file that is only a mark is empty.
    assert_eq!(parse_dev(&f, "\u{feff}\n").unwrap_err(), PlanFileError::Empty);
}

#[test]
fn empty_and_blank_files_are_refused() {
    let f = fixture();
    for body in ["", "\n\n", "  \n\t\n"] {
        assert_eq!(parse_dev(&f, body).unwrap_err(), PlanFileError::Empty);
    }
}

#[test]
fn step_length_counts_characters_not_bytes() {
    let f = fixture();
    let body = format!(r#"{{"id": "dev-0001", "plan": ["{}"]}}"#, "é".repeat(200));
    assert!(parse_dev(&f, &body).is_ok());
}

#[test]
fn line_at_counts_newlines_before_the_limit() {
    assert_eq!(line_at(b"ab\ncd\nef", 4), 2);
    assert_eq!(line_at(b"abc", 10), 1);
}

proptest! {
    #[test]
    fn parser_never_panics_on_arbitrary_bytes(body in proptest::collection::vec(any::<u8>(), 0..512)) {
        let f = fixture();
        let _ = parse(&body, Split::Dev, f.dev.len(), &f.index, &PlanLimits::default());
    }

    #[test]
    fn parser_never_panics_on_json_like_lines(
        lines in proptest::collection::vec("[{}\\[\\]\",:a-z0-9 \\-]{0,40}", 0..8)
    ) {
        let f = fixture();
        let body = lines.join("\n");
        let _ = parse(body.as_bytes(), Split::Dev, f.dev.len(), &f.index, &PlanLimits::default());
    }
}
