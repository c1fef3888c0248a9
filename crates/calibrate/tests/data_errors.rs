//! Bad data sets give errors naming the line, sample and cable, not panics.

use calibrate::from_dataset;
use calibrate::observation::ObservationError;

#[test]
fn bad_data_sets_are_rejected_with_a_reason() {
    let text = "# format: crs-dataset 1\n# units: SI (q_cmd m; x y z m; phi rad, R = Rx Ry Rz eq. 2.2; f N)\nsample,q_cmd_1,x,y,z,phi_x,phi_y,phi_z\n0,1.0,0,0,oops,0,0,0\n";
    let err = crs_dataset::read_dataset(text.as_bytes(), "bad.csv").unwrap_err();
    assert_eq!(err.line, Some(4), "{err}");
    let ok = "# format: crs-dataset 1\n# units: SI (q_cmd m; x y z m; phi rad, R = Rx Ry Rz eq. 2.2; f N)\nsample,q_cmd_1,x,y,z,phi_x,phi_y,phi_z,f_1\n0,1.0,0,0,1,0,0,0,-5\n";
    let ds = crs_dataset::read_dataset(ok.as_bytes(), "one.csv").unwrap();
    assert_eq!(
        from_dataset(&ds, 8),
        Err(ObservationError::CableCount {
            expected: 8,
            got: 1
        })
    );
    assert!(matches!(
        from_dataset(&ds, 1),
        Err(ObservationError::NonPositiveForce {
            sample: 0,
            cable: 1,
            ..
        })
    ));
}
