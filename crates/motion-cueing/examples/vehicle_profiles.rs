//! Writes the shipped vehicle profiles (`motion_cueing::profiles`) as vehicle CSVs:
//! `cargo run -p motion-cueing --example vehicle_profiles -- config/vehicle`.
//! The test `profiles_on_disk` checks the files in config/vehicle/ equal this output.
use motion_cueing::profiles::{PROFILES, header};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: vehicle_profiles DIR")?,
    );
    std::fs::create_dir_all(&dir)?;
    for p in &PROFILES {
        let path = dir.join(format!("{}.csv", p.name));
        (p.make)().write_csv(&path, &header(p))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
