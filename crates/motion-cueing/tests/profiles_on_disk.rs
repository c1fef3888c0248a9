//! The vehicle CSVs shipped in config/vehicle/ are what the generator writes (regenerate with
//! `cargo run -p motion-cueing --example vehicle_profiles -- config/vehicle`), and they read
//! back through the documented CSV reader.
use motion_cueing::VehicleTrack;
use motion_cueing::profiles::{PROFILES, header};
use std::path::Path;

#[test]
fn shipped_profiles_equal_the_generator_and_read_back() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/vehicle");
    for p in &PROFILES {
        let path = dir.join(format!("{}.csv", p.name));
        let on_disk =
            std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let made = (p.make)().to_csv(&header(p)).unwrap();
        assert!(
            on_disk == made,
            "{} differs from the generator's output: regenerate it",
            path.display()
        );
        let t = VehicleTrack::read_csv(&path).unwrap();
        assert!(t.duration_s() > 10.0, "{}", p.name);
    }
}
