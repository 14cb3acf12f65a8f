//! Runs the Python package's tests (tests/python_package.py): a trial from
//! Python equals the command line's bit for bit, errors carry its message,
//! Ctrl-C stops a run cleanly, a drape equals `drape`'s; sweeps on a local
//! Dask cluster of two workers write the Parquet table that pandas and polars
//! read back, record a bad pattern's error as a row, run a killed worker's
//! trial again and once, and redo nothing when run again. In a network
//! namespace of its own: the cluster talks over loopback only. The package
//! is built and installed by tests/run.sh (maturin); without it this test
//! fails and says so.

mod support;

#[test]
fn the_python_package_runs_trials_and_sweeps() {
    let dir = support::Scratch::new("python_package");
    let bin = std::ffi::OsString::from(support::garment_sim_path());
    support::pytest(
        "tests/python_package.py",
        "garment_sim, dask.distributed, pyarrow, polars, pandas, yaml, numpy, pytest",
        true,
        &[
            ("GARMENT_SIM_BIN", &bin),
            ("GARMENT_SIM_TMP", dir.as_os_str()),
        ],
        "9 passed",
    );
}
