//! What the operator can export from the Inspect view, named for the
//! commands that ask for an export (`app::commands`) and for the view that
//! builds and writes it (`views::inspect`), so neither imports the other.

/// What the operator can export from the Inspect view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ExportKind {
    ProfilesCsv,
    ProfilePlotPng,
    MeasurementsCsv,
    MapX3p,
    MapTiff,
    MapPng,
    CloudPly,
    ReportPdf,
    ReportHtml,
    /// The part's results as a Q-DAS AQDEF transfer file.
    Dfq,
    /// The part's results as a QIF 3.0 Results document.
    Qif,
    Session,
    /// The session and the height map as a line's recipe (`sheen watch`).
    Recipe,
}

impl ExportKind {
    pub const ALL: [ExportKind; 11] = [
        ExportKind::ProfilesCsv,
        ExportKind::ProfilePlotPng,
        ExportKind::MeasurementsCsv,
        ExportKind::MapX3p,
        ExportKind::MapTiff,
        ExportKind::MapPng,
        ExportKind::CloudPly,
        ExportKind::ReportPdf,
        ExportKind::ReportHtml,
        ExportKind::Dfq,
        ExportKind::Qif,
    ];

    /// Whether the export describes the part (its record's facts: part,
    /// recipe, time, station, operator), not only what is measured.
    pub fn needs_part_facts(self) -> bool {
        matches!(self, ExportKind::ReportPdf | ExportKind::ReportHtml | ExportKind::Dfq | ExportKind::Qif)
    }

    /// Button text.
    pub fn label(self) -> &'static str {
        match self {
            ExportKind::ProfilesCsv => "Profiles CSV",
            ExportKind::ProfilePlotPng => "Profile plot PNG",
            ExportKind::MeasurementsCsv => "Measurements CSV",
            ExportKind::MapX3p => "Height map X3P",
            ExportKind::MapTiff => "Height map TIFF",
            ExportKind::MapPng => "Height map PNG",
            ExportKind::CloudPly => "Point cloud PLY",
            ExportKind::ReportPdf => "Report PDF",
            ExportKind::ReportHtml => "Report HTML",
            ExportKind::Dfq => "AQDEF (.dfq)",
            ExportKind::Qif => "QIF results",
            ExportKind::Session => "Session",
            ExportKind::Recipe => "Recipe",
        }
    }

    pub fn tooltip(self) -> &'static str {
        match self {
            ExportKind::ProfilesCsv => {
                "Every profile as CSV (distance, x, y, z in mm and µm; header with source, end points, width, step and \
                 interpolation); one file per profile when there are several."
            }
            ExportKind::ProfilePlotPng => "The profile plot as a PNG image, with axes, legend and cursors.",
            ExportKind::MeasurementsCsv => "The measurement table with units, limits and pass/fail as CSV.",
            ExportKind::MapX3p => {
                "The height map (levelled when levelling is on, holes never filled) as ISO 25178-72 X3P, as read by \
                 Gwyddion and the openGPS tools."
            }
            ExportKind::MapTiff => {
                "The height map as a 32-bit float TIFF in µm, north up, NaN for holes (levelled when levelling is on)."
            }
            ExportKind::MapPng => "The height map as shown (colour map and range) with its colour bar in µm, as PNG.",
            ExportKind::CloudPly => "The result's point cloud as binary PLY (CloudCompare, MeshLab).",
            ExportKind::ReportPdf | ExportKind::ReportHtml => {
                "The part's report on one A4 page: part, recipe, time, station, operator (from Record), the verdict, \
                 the height map with regions and sections, the profiles, the measurement table, the engine \
                 parameters and the input's hash."
            }
            ExportKind::Dfq => {
                "The part's values, limits and verdict as a Q-DAS AQDEF transfer file for the plant's SPC \
                 (qs-STAT, O-QIS, procella): part number (the recipe), part ID, time, station, operator and gauge \
                 from Record."
            }
            ExportKind::Qif => {
                "The part's results as a QIF 3.0 Results document (ISO 23952): each characteristic with its \
                 tolerance, value, standard uncertainty and status, the part's serial and verdict."
            }
            ExportKind::Session => "The manifest, parameters and the whole inspection as a session JSON file.",
            ExportKind::Recipe => {
                "This part as a line's recipe: the session plus its height map (NAME.reference.x3p beside it), \
                 which each new part is found against so the regions follow it (sheen watch, sheen analyze \
                 --recipe, the Line view)."
            }
        }
    }

    pub fn default_file_name(self) -> &'static str {
        match self {
            ExportKind::ProfilesCsv => "profiles.csv",
            ExportKind::ProfilePlotPng => "profiles.png",
            ExportKind::MeasurementsCsv => "measurements.csv",
            ExportKind::MapX3p => "height_map.x3p",
            ExportKind::MapTiff => "height_map.tif",
            ExportKind::MapPng => "height_map.png",
            ExportKind::CloudPly => "cloud.ply",
            ExportKind::ReportPdf => "report.pdf",
            ExportKind::ReportHtml => "report.html",
            ExportKind::Dfq => "part.dfq",
            ExportKind::Qif => "part.qif",
            ExportKind::Session => "inspection.sheen-session.json",
            ExportKind::Recipe => "part.sheen-recipe.json",
        }
    }

    pub fn filter(self) -> (&'static str, &'static [&'static str]) {
        match self {
            ExportKind::ProfilesCsv | ExportKind::MeasurementsCsv => ("CSV", &["csv"]),
            ExportKind::ProfilePlotPng | ExportKind::MapPng => ("PNG image", &["png"]),
            ExportKind::MapX3p => ("X3P (ISO 25178-72)", &["x3p"]),
            ExportKind::MapTiff => ("TIFF", &["tif", "tiff"]),
            ExportKind::CloudPly => ("PLY point cloud", &["ply"]),
            ExportKind::ReportPdf => ("PDF report", &["pdf"]),
            ExportKind::ReportHtml => ("HTML report", &["html", "htm"]),
            ExportKind::Dfq => ("Q-DAS AQDEF", &["dfq"]),
            ExportKind::Qif => ("QIF 3.0", &["qif", "xml"]),
            ExportKind::Session => ("Sheen session", &["json"]),
            ExportKind::Recipe => ("Sheen recipe", &["json"]),
        }
    }
}
