//! Exchange files (issue 51): what writing a part's Q-DAS AQDEF file and
//! QIF 3.0 Results document adds to a part on the line. The part is the
//! line's own (`tests/line-spec.json`: two steps, an RMS flatness and every
//! ISO 25178-2 texture parameter of a region, each with its uncertainty),
//! measured once by `sheen analyze` on a simulated step gauge; the size of
//! the map does not enter, only the rows. Timed: the two documents built
//! in memory, and both written atomically (temporary file, sync, rename)
//! as the watch writes them. `cargo bench --bench exchange`.

use criterion::{Criterion, criterion_group, criterion_main};
use sheen::analysis::measurement_record::MeasurementRecord;
use sheen::analysis::measurement_table::PartVerdict;
use sheen::cli::AnalyzeArgs;
use sheen::engine::control::RunControl;
use sheen::io::dataset::{ImageFileFormat, write_measurement_as};
use sheen::io::exchange::ExchangePart;
use sheen::sim::{SceneKind, SimConfig, simulate};

fn measured_part(dir: &std::path::Path) -> ExchangePart {
    let mut config = SimConfig::new(SceneKind::StepGauge, 512, 384);
    config.noise_sigma_dn = 1.0;
    let sim = simulate(&config, &RunControl::new()).expect("simulate");
    let set = dir.join("part");
    write_measurement_as(&set, &sim.measurement, ImageFileFormat::Tiff).expect("write the part");
    let spec = dir.join("line-spec.json");
    std::fs::write(&spec, include_str!("../tests/line-spec.json")).expect("spec");
    let mut args = AnalyzeArgs::new(Some(set.join(sheen::io::dataset::MANIFEST_FILE)), dir.join("out"));
    args.spec = Some(spec);
    args.quiet = true;
    let table = sheen::cli::analyze::analyze(&args).expect("analyze");
    ExchangePart {
        part_id: "part-0001".into(),
        part_number: "gauge".into(),
        description: None,
        operation: None,
        time_utc: chrono::Utc::now(),
        station: Some("line 1".into()),
        operator: Some("operator".into()),
        gauge: ExchangePart::gauge_name(env!("CARGO_PKG_VERSION"), Some("calibration.json")),
        verdict: PartVerdict::of_table(&table).0,
        reason: None,
        measurements: table.rows.iter().map(MeasurementRecord::from_row).collect(),
    }
}

fn benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let part = measured_part(dir.path());
    eprintln!("exchange: a part of {} measurements", part.measurements.len());
    let version = env!("CARGO_PKG_VERSION");
    c.bench_function("exchange_documents_in_memory", |b| {
        b.iter(|| {
            let dfq = sheen::io::aqdef::dfq_bytes(std::slice::from_ref(&part));
            let qif = sheen::io::qif::qif_document(&part, version);
            (dfq.len(), qif.len())
        })
    });
    let (dfq, qif) = (dir.path().join("part.dfq"), dir.path().join("part.qif"));
    c.bench_function("exchange_files_written_atomically", |b| {
        b.iter(|| {
            sheen::io::aqdef::write_dfq(&dfq, std::slice::from_ref(&part)).expect("dfq");
            sheen::io::qif::write_qif(&qif, &part, version).expect("qif");
        })
    });
}

criterion_group!(exchange, benches);
criterion_main!(exchange);
