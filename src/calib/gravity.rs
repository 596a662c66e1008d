//! Local gravity from WGS-84 normal gravity (Somigliana's formula with the
//! second-order free-air correction; NIMA TR8350.2, eq. 4-1 and 4-3).

const GAMMA_E: f64 = 9.780_325_335_9; // equatorial normal gravity [m/s²]
const K_SOMIGLIANA: f64 = 0.001_931_852_652_41;
const E2: f64 = 0.006_694_379_990_13; // first eccentricity squared
const A: f64 = 6_378_137.0; // semi-major axis [m]
const F: f64 = 1.0 / 298.257_223_563; // flattening
const M: f64 = 0.003_449_786_506_84; // ω²a²b/GM

/// WGS-84 normal gravity \[m/s²\] at geodetic `latitude_deg` \[°\] and
/// ellipsoidal `height_m` \[m\] (valid for heights of a few km).
///
/// ```
/// let g = tumble::calib::normal_gravity(45.0, 0.0);
/// assert!((g - 9.806_197_8).abs() < 1e-6);
/// ```
pub fn normal_gravity(latitude_deg: f64, height_m: f64) -> f64 {
    let s2 = latitude_deg.to_radians().sin().powi(2);
    let g0 = GAMMA_E * (1.0 + K_SOMIGLIANA * s2) / (1.0 - E2 * s2).sqrt();
    g0 * (1.0 - 2.0 / A * (1.0 + F + M - 2.0 * F * s2) * height_m + 3.0 * height_m * height_m / (A * A))
}

/// Largest ellipsoidal height [`local_gravity`] takes \[m\]: above Everest and
/// airliners, where the second-order free-air formula is still accurate.
pub const MAX_HEIGHT_M: f64 = 20_000.0;

/// Local gravity and how it was found (see [`local_gravity`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalGravity {
    /// Gravity magnitude \[m/s²\].
    pub value: f64,
    /// A note for the user when nothing was given and standard gravity is used.
    pub note: Option<&'static str>,
}

/// Gravity from what the user gave: the value itself, or WGS-84 normal
/// gravity at a latitude \[°\] and height \[m\], or (neither) standard
/// gravity, with a note saying so.
pub fn local_gravity(
    gravity: Option<f64>,
    latitude_deg: Option<f64>,
    height_m: f64,
) -> Result<LocalGravity, crate::OptionError> {
    let value = match (gravity, latitude_deg) {
        (Some(g), _) => g,
        (None, Some(lat)) => {
            if !(-90.0..=90.0).contains(&lat) {
                return Err(crate::OptionError::new("--latitude", format!("must be within ±90°, got {lat}")));
            }
            if height_m.is_nan() || height_m.abs() > MAX_HEIGHT_M {
                return Err(crate::OptionError::new(
                    "--height",
                    format!(
                        "must be within ±{MAX_HEIGHT_M} m (the normal-gravity formula holds near the surface), got {height_m}"
                    ),
                ));
            }
            normal_gravity(lat, height_m)
        }
        (None, None) => {
            return Ok(LocalGravity {
                value: crate::model::STANDARD_GRAVITY,
                note: Some("no --gravity or --latitude given; using standard gravity 9.80665 m/s²"),
            })
        }
    };
    Ok(LocalGravity { value, note: None })
}

#[cfg(test)]
mod tests {
    use super::normal_gravity;
    #[test]
    fn reference_values() {
        assert!((normal_gravity(0.0, 0.0) - 9.780_325_3).abs() < 1e-7);
        assert!((normal_gravity(90.0, 0.0) - 9.832_184_9).abs() < 1e-7);
        // Free-air gradient ≈ −3.086e-6 s⁻² near the surface.
        let grad = (normal_gravity(45.0, 100.0) - normal_gravity(45.0, 0.0)) / 100.0;
        assert!((grad + 3.086e-6).abs() < 2e-9, "{grad}");
    }
}
