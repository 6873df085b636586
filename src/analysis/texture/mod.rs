//! Surface texture: ISO 16610 filters and ISO 25178-2 areal parameters.
//!
//! Flow: heights (µm, holes NaN) → F-operator ([`filter::remove_form`]) →
//! S-filter (Gaussian mean surface at λs, [`filter::gaussian_areal_mean_surface`])
//! → optional L-filter (subtract the Gaussian mean surface at λc) → the
//! scale-limited surface → [`areal::areal_parameters`]. Holes stay holes at
//! every stage and are never read as heights.

pub mod areal;
pub mod filter;
pub mod material_ratio;
pub mod measure;
pub mod profile_params;
pub mod spatial;
