//! SOEM (pysoem) against twins of vendors' devices (issue 16): for every ESI file under
//! the reference's `esi/` and `esi-vendor/`, the first device type oxicat serves as a twin
//! is served by `oxicat sim esi=FILE:TYPE` on a veth pair and driven by
//! `soem/soem_check.py`: scan (identity and the name SOEM shows), SAFEOP, OP, process data
//! without a working-counter error; for twins the slave stack serves (with a mailbox) also
//! the SDO checks (0x1018, strings, abort codes, a write read back), DC SYNC0 where the ESI
//! has it, and the SM watchdog path. Twins served by their ESC alone get the first group.
//!
//! Needs root and pysoem (as `soem_netns.rs`); skipped with the reason elsewhere, mandatory
//! in CI.

mod netns_common;
mod soem_common;

use std::path::PathBuf;

use netns_common::NetnsSim;
use oxicat_esi::twin::Served;
use oxicat_testkit::served::{esi_files, TWIN_REFUSALS_ALLOWED};
use soem_common::{python_with_pysoem, spec_of, Drive, Expect, Results};

/// The ESI files of the reference, or those whose path holds `OXICAT_SOEM_ESI` (for
/// looking at one by hand).
fn files() -> Vec<PathBuf> {
    let mut v = esi_files();
    if let Ok(only) = std::env::var("OXICAT_SOEM_ESI") {
        v.retain(|p| p.to_string_lossy().contains(&only));
    }
    v
}

#[test]
fn soem_runs_a_twin_of_each_esi_file_over_a_veth() {
    if NetnsSim::bare().is_none() {
        return;
    }
    let py = match python_with_pysoem() {
        Ok(p) => p,
        Err(e) => {
            assert!(!netns_common::in_ci(), "SOEM test cannot run in CI: {e}");
            eprintln!("skipped: {e}");
            return;
        }
    };
    let drive = Drive {
        cycles: 300,
        cycle_ns: 1_000_000,
        nodes: 1,
        slowdown: 1,
        watchdog_ms: None,
    };
    let mut failed = Vec::new();
    let mut driven = 0;
    let mut refused = Vec::new();
    for f in files() {
        let all = oxicat_devices::twin::load_file(&f).unwrap_or_else(|e| panic!("{e}"));
        let reasons: Vec<String> = all
            .iter()
            .filter_map(|(c, r)| r.as_ref().err().map(|e| format!("{}: {e}", c.type_name)))
            .collect();
        let Some(t) = all.into_iter().find_map(|(_, r)| r.ok()) else {
            // A file none of whose types is served: only for a limit the catalogue walk
            // accepts too (`twin_catalogue.rs`), reported.
            for r in reasons {
                if TWIN_REFUSALS_ALLOWED.iter().any(|(p, _)| r.contains(p)) {
                    refused.push(format!("{}: {r}", f.display()));
                } else {
                    failed.push(format!("{}: refused: {r}", f.display()));
                }
            }
            continue;
        };
        let firmware = t.esi.served == Served::Stack;
        // By product code and revision: type names may hold spaces.
        let id = t.esi.def.identity;
        let name = format!(
            "esi={}:{:#x}:{:#x}",
            f.display(),
            id.product_code,
            id.revision
        );
        let Some(bench) = NetnsSim::start(&[&name]) else {
            return;
        };
        let (spec, _) = spec_of(
            &[Expect {
                def: t.esi.def,
                stack: firmware,
                order_code: t.esi.candidate.type_name.clone(),
                name: t.esi.candidate.name.clone(),
            }],
            drive,
        );
        let mut results = Results::new();
        soem_common::drive_spec(&py, &bench, &name, &name, &spec, &mut results);
        drop(bench);
        driven += 1;
        let mut want = vec![
            "scan_identity",
            "scan_name",
            "to_safeop",
            "pd_map",
            "to_op",
            "pdo_exchange",
        ];
        if firmware {
            want.extend([
                "sdo_read_identity",
                "sdo_pdo_assign",
                "sdo_abort_missing_object",
            ]);
        }
        for c in want {
            if !results.contains_key(c) {
                failed.push(format!("{name}: {c} did not run"));
            }
        }
        for (c, rows) in &results {
            for (_, _, ok, detail) in rows {
                if !ok {
                    failed.push(format!("{name}: {c}: {detail}"));
                }
            }
        }
    }
    eprintln!(
        "SOEM drove {driven} twins; files with no type served ({}):\n  {}",
        refused.len(),
        refused.join("\n  ")
    );
    if std::env::var_os("OXICAT_SOEM_ESI").is_none() {
        assert!(driven >= 10, "{driven} ESI files driven");
    }
    assert!(
        failed.is_empty(),
        "SOEM on twins:\n  {}",
        failed.join("\n  ")
    );
}
