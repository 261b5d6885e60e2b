//! A Kalman filter over measurements read from a CSV file, with gaps.
//!
//! `examples/data/positions.csv` holds `time,x,y`: positions of a 2-D target at 1 Hz with
//! 10 m noise per axis; rows with empty cells are steps without a measurement (a dropout at
//! 20-24 s). The filter predicts through the gap and its covariance grows there; with no truth
//! at hand, the normalised innovations (NIS) against their chi-square band are the check that
//! the filter's covariance tells the truth.
//!
//! Run with `cargo run --example kf_from_csv [FILE]`.

#![allow(clippy::print_stdout)]

use kalibra::prelude::*;

/// The measurements of a `time,x,y` file: one entry per row, `None` where the row is empty.
fn read_positions(path: &str) -> Result<Vec<Option<Vector2<f64>>>, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, header)) if header.trim() == "time,x,y" => {}
        _ => return Err(format!("{path}: line 1: expected the header `time,x,y`")),
    }
    let mut out = Vec::new();
    for (index, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        let at = |what: &str| format!("{path}: line {}: {what}", index + 1);
        if cells.len() != 3 {
            return Err(at(&format!("expected 3 cells, found {}", cells.len())));
        }
        if cells[1].is_empty() && cells[2].is_empty() {
            out.push(None);
            continue;
        }
        let number = |column: usize, name: &str| {
            cells[column]
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    at(&format!(
                        "column {name}: {:?} is not a number",
                        cells[column]
                    ))
                })
        };
        out.push(Some(Vector2::new(number(1, "x")?, number(2, "y")?)));
    }
    Ok(out)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).unwrap_or_else(|| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/examples/data/positions.csv").into()
    });
    let measurements = read_positions(&path)?;

    let cv = Kinematic::constant_velocity(2, 1.0)?.noise(ProcessNoise::Discrete { q: 1.0 });
    let f = cv.dynamics(U4)?;
    let h = cv.position_measurement(U4, U2, Matrix2::identity() * 100.0)?;
    // A vague start at the first measurement's position, speed unknown (sd 30 m/s).
    let first = measurements
        .iter()
        .flatten()
        .next()
        .ok_or("the file has no measurement")?;
    let x0 = Vector4::new(first[0], first[1], 0.0, 0.0);
    let p0 = Matrix4::from_diagonal(&Vector4::new(100.0, 100.0, 900.0, 900.0));
    let mut kf = Kf::new(&f, &h, x0, p0)?;

    println!("| time | x | y | vx | vy | sd x | NIS |");
    println!("|---|---|---|---|---|---|---|");
    let mut nis = Vec::new();
    for (k, z) in measurements.iter().enumerate() {
        if k > 0 {
            kf.predict()?;
        }
        let shown = match z {
            Some(z) => {
                let record = kf.update(z).map_err(|e| format!("step {k}: {e}"))?;
                nis.push(record.nis());
                format!("{:.2}", record.nis())
            }
            None => "no measurement".into(),
        };
        let (x, p) = (kf.mean(), kf.covariance());
        if k % 5 == 0 || z.is_none() {
            println!(
                "| {k} | {:.1} | {:.1} | {:.2} | {:.2} | {:.1} | {shown} |",
                x[0],
                x[1],
                x[2],
                x[3],
                p[(0, 0)].sqrt()
            );
        }
    }
    // NIS / m averaged over the updates, against its 95% band (the updates of one run are
    // nearly independent for a consistent filter, so the band over time applies).
    let band = ChiSquareBand::for_normalized_mean(2.0, nis.len(), 0.95)?;
    let average = nis.iter().sum::<f64>() / nis.len() as f64 / 2.0;
    println!(
        "\n{} updates; time-averaged NIS / 2 = {average:.3}, 95% band [{:.3}, {:.3}]: {}",
        nis.len(),
        band.lower,
        band.upper,
        if band.contains(average) {
            "consistent"
        } else if average > band.upper {
            "optimistic (covariance too small)"
        } else {
            "pessimistic (covariance too large)"
        }
    );
    Ok(())
}
