//! Writes the committed fixtures `tests/fixtures/kf.json` and `kf.csv` from the seeded
//! simulation in `common`. Run once when the fixture format changes:
//! `cargo test -p kalibra-cli --test generate_fixtures -- --ignored`.

mod common;

#[test]
#[ignore = "writes the committed fixtures; run by hand"]
fn generate_fixtures() {
    let (runs, model) = common::simulate();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("kf.json"), common::to_json(&runs, &model)).unwrap();
    std::fs::write(dir.join("kf.csv"), common::to_csv(&runs)).unwrap();
}
