//! Why an analysis cannot be carried out. Measurements on partly invalid data
//! are not errors (holes are skipped and counted); these variants are for
//! input that leaves nothing meaningful to compute, and each message says what
//! was expected, what was found and what to do about it.

/// Errors of height-map building, region measurements, profiles and specs.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    /// The owner of the run stopped it (a newer inspection, the operator).
    #[error("cancelled")]
    Cancelled(#[from] crate::engine::control::Cancelled),
    #[error("its points do not span an area in X-Y, so they cannot be binned into a height map; give --pitch-mm")]
    NoArea,
    #[error(
        "the point cloud has {points} points but {pixels} left-camera pixel coordinates; a height map needs the \
         organized cloud (every point's pixel), so reconstruct again or load a PLY that carries u and v"
    )]
    NotOrganized { points: usize, pixels: usize },
    #[error(
        "the point cloud's pixel coordinates span {width}x{height} px, more than the {max_pixels} pixels of any \
         supported camera; the u, v columns of this cloud are not camera pixels"
    )]
    PixelGridTooLarge { width: usize, height: usize, max_pixels: usize },
    #[error("the height-map pitch {pitch_mm} mm is not a positive finite length; give a pitch such as 0.01 mm")]
    InvalidPitch { pitch_mm: f64 },
    #[error(
        "no surface survives triangulation: of {quads} pixel quads with points, {long_edge} were cut for edges longer \
         than {max_edge_pitches} pitches and {jump} for height jumps; check the pitch (now {pitch_mm} mm) and the \
         discontinuity limits"
    )]
    NoSurface { quads: usize, long_edge: usize, jump: usize, max_edge_pitches: f64, pitch_mm: f64 },
    #[error(
        "a {width}x{height} height map at pitch {pitch_mm} mm would hold more than {max_nodes} nodes; use a coarser \
         pitch or crop the cloud"
    )]
    MapTooLarge { width: usize, height: usize, pitch_mm: f64, max_nodes: usize },
    #[error("height map holds {found} values for {width}x{height} nodes; expected width x height values")]
    MapShape { width: usize, height: usize, found: usize },
    #[error("region '{name}': {reason}")]
    InvalidRegion { name: String, reason: String },
    #[error("recipe: {reason}")]
    InvalidRecipe { reason: String },
    #[error(
        "region '{region}' covers {found} valid height-map samples, at least {needed} are needed; enlarge or move the \
         region onto measured surface (holes are never used)"
    )]
    TooFewSamples { region: String, found: usize, needed: usize },
    #[error(
        "{region}: the L-filter cut-off λc {cutoff_mm} mm exceeds the region's extent {extent_mm:.4} mm, so every \
         height would rest on a partial kernel; choose λc of at most the region's longer side or enlarge the \
         region"
    )]
    CutoffBeyondRegion { region: String, cutoff_mm: f64, extent_mm: f64 },
    #[error(
        "region '{region}': its {samples} valid samples lie on one line, so no plane is defined; draw a region with \
         extent in both X and Y"
    )]
    CollinearSamples { region: String, samples: usize },
    #[error("coplanarity needs at least 2 lands, {found} given")]
    TooFewLands { found: usize },
    #[error("profile '{name}': {reason}")]
    InvalidProfile { name: String, reason: String },
    #[error("{used_by} refers to region '{name}', which is not defined; defined regions: {defined}")]
    UnknownRegion { name: String, used_by: String, defined: String },
    #[error("two {kind}s are named '{name}'; names must be unique so results can be told apart")]
    DuplicateName { kind: &'static str, name: String },
    #[error("measurement '{name}': tolerance {lower} .. {upper} is not an interval (finite, lower <= upper)")]
    InvalidTolerance { name: String, lower: f64, upper: f64 },
    #[error("measurement '{name}': {reason}")]
    InvalidMeasurement { name: String, reason: String },
    #[error(
        "this {what} has format version {found}, this Sheen reads version {supported}; open it with the Sheen that \
         wrote it or re-create it"
    )]
    UnsupportedVersion { what: &'static str, found: u64, supported: u64 },
    #[error("this is not a Sheen {what}: the field '{field}' that names its format version is missing")]
    MissingVersion { what: &'static str, field: &'static str },
    #[error("this {what} is not valid JSON for Sheen: {source}")]
    Json {
        what: &'static str,
        #[source]
        source: serde_json::Error,
    },
}
