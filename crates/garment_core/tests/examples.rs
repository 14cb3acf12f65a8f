//! The examples run, and what they print holds.

#[allow(dead_code)] // its `main` is the example's
#[path = "../examples/hang.rs"]
mod hang;

/// `examples/hang.rs`: the cloth weighs its areal mass times its area, the
/// held corners stay put, the centre of mass falls, but less than free fall
/// (the pins hold it up), and the implicit step creates no energy.
#[test]
fn the_hanging_square_example_holds_its_corners_and_falls_slower_than_free_fall() {
    let h = hang::run().unwrap();
    assert_eq!(h.vertices, 21 * 21);
    assert!(
        (h.mass - h.expected_mass).abs() <= 1e-12 * h.expected_mass,
        "mass {} against {}",
        h.mass,
        h.expected_mass
    );
    assert!(
        h.held_moved <= 1e-12,
        "held corners moved {} m",
        h.held_moved
    );
    assert!((h.time - 0.2).abs() < 1e-9, "{} s", h.time);
    let free_fall = 0.5 * 9.81 * h.time * h.time;
    assert!(
        h.fall > 0.1 * free_fall && h.fall < free_fall,
        "fell {} m, free fall {free_fall} m",
        h.fall
    );
    assert!(
        h.energy_end <= h.energy_start + 1e-9,
        "energy {} J → {} J",
        h.energy_start,
        h.energy_end
    );
    assert!(h.iterations >= 1.0, "{} iterations per step", h.iterations);
}
