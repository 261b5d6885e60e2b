//! The committed fixtures `tests/fixtures/kf.json`, `kf.csv` and the tuning fixtures
//! `tune_model.toml`, `tune_measurements.csv`, `tune_truth.csv` and the noise-estimation
//! fixtures `noise_model.toml`, `noise_measurements.csv`, `noise_truth.csv` are exactly what the seeded
//! simulation in `common` writes, so the end-to-end tests' inputs cannot drift from the code
//! that describes them. After a deliberate change of the fixture format, rewrite them with
//! `KALIBRA_BLESS=1 cargo test -p kalibra-cli --test generate_fixtures`.

use crate::common;

#[test]
fn committed_fixtures_are_the_seeded_simulation() {
    let (runs, model) = common::simulate();
    let (zs, xs) = common::simulate_tune();
    let (noise_zs, noise_xs) = common::simulate_noise();
    let noise_zs: Vec<Option<f64>> = noise_zs.into_iter().map(Some).collect();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let expected = [
        ("kf.json", common::to_json(&runs, &model)),
        ("kf.csv", common::to_csv(&runs)),
        ("tune_model.toml", common::tune_model_toml()),
        ("tune_measurements.csv", common::tune_measurements_csv(&zs)),
        ("tune_truth.csv", common::tune_truth_csv(&xs)),
        ("noise_model.toml", common::noise_model_toml()),
        (
            "noise_measurements.csv",
            common::tune_measurements_csv(&noise_zs),
        ),
        ("noise_truth.csv", common::tune_truth_csv(&noise_xs)),
    ];
    let bless = std::env::var_os("KALIBRA_BLESS").is_some();
    for (name, text) in expected {
        let path = dir.join(name);
        if bless {
            std::fs::create_dir_all(&dir).unwrap();
            std::fs::write(&path, &text).unwrap();
        }
        let committed = std::fs::read_to_string(&path).unwrap();
        assert!(
            committed == text,
            "{name} differs from the seeded simulation; rewrite it with KALIBRA_BLESS=1"
        );
    }
}
