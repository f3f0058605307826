//! `frfit reduce` and balanced truncation on the wafer stage: on the true 4 x 13 plant
//! (17 lightly damped modes and a double integrator) the H-infinity error measured on a
//! dense grid is within the a-priori bound `2 sum(discarded Hankel singular values)` at
//! every order tried and the integrators come back exactly; through the CLI the written
//! model file holds the bound and the values in its provenance, its response is within
//! the bound of the original's, and bad orders are refused with the reason.

mod common;
use common::*;
use faer::Mat;
use frf_data::shared_data::require;
use frf_data::truth::Truth;
use frfit::additive_riv::{AdditiveModel, Domain, ModelFile, Provenance};
use frfit::reduce::additive_from_modal;
use realize::balanced::{hinf_grid, max_sv_difference};
use realize::{balanced_truncation, BalancedTruncation, ModalModel};
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

/// A model file holding `modal` exactly, in continuous time or through the exact hold.
fn model_file(modal: &ModalModel, domain: Domain, path: &Path) -> ModelFile {
    let mut template = AdditiveModel::new(modal.ny, modal.nu, domain).unwrap();
    if !modal.rigid.is_empty() {
        template
            .push_rigid_body(modal.rigid.len(), TAU * 300.0)
            .unwrap();
    }
    let am = additive_from_modal(&template, modal).unwrap();
    let file = ModelFile::from_model(
        &am,
        Some("m/N".into()),
        Some((1.0, 4000.0)),
        Provenance {
            estimator: "truth".into(),
            ..Default::default()
        },
    )
    .unwrap();
    file.write(path).unwrap();
    file
}

/// The rational part of a model file, as the file rebuilds it.
fn modal_of(file: &ModelFile) -> ModalModel {
    file.to_model().unwrap().to_frf_model_exact().unwrap().modal
}

fn assert_same_rigid(a: &ModalModel, b: &ModalModel, tol: f64) {
    assert_eq!(a.rigid.len(), b.rigid.len());
    for (x, y) in a.rigid.iter().zip(&b.rigid) {
        let d = (x - y).norm_l2();
        assert!(d <= tol * y.norm_l2(), "rigid body changed by {d:.3e}");
    }
}

fn wafer_truth() -> Option<ModalModel> {
    let path = require("reduce_wafer", "wafer_nominal.truth.json")?;
    Some(Truth::read(path).unwrap().modal_model().unwrap())
}

#[test]
fn wafer_stage_errors_are_within_the_bound_and_the_integrators_are_kept() {
    let Some(m) = wafer_truth() else { return };
    let an = BalancedTruncation::default().analyse(&m).unwrap();
    // rank-3 b_rb of the 4 x 13 stage: three double-integrator chains; 17 rank-one modes
    assert_eq!((an.rigid_order, an.stable_order), (6, 34));
    let top = an.hankel_singular_values[0];
    for order in [10, 20, 30, 36, 40] {
        let red = balanced_truncation(&m, order).unwrap();
        assert_eq!(
            red.model.rigid, m.rigid,
            "order {order}: integrators not kept"
        );
        assert_eq!(red.model.feedthrough, m.feedthrough);
        let grid = hinf_grid(&[&m, &red.model], 300);
        let err = max_sv_difference(&m, &red.model, &grid).unwrap();
        println!(
            "wafer order {order}: measured {err:.4e}, bound {:.4e}, conversion {:.1e}",
            red.error_bound, red.conversion_error
        );
        assert!(
            err <= red.error_bound * (1.0 + 1e-6) + 2.0 * red.conversion_error + 1e-10 * top,
            "order {order}: measured {err:.6e} > bound {:.6e}",
            red.error_bound
        );
        if order < 40 {
            // the bound is not vacuous: the error is within a factor 2 .. 20 of it
            assert!(
                err > red.error_bound / 20.0,
                "order {order}: {err:e} vs {:e}",
                red.error_bound
            );
        }
    }
}

#[test]
fn wafer_stage_model_files_round_trip_exactly_in_both_time_variables() {
    let Some(m) = wafer_truth() else { return };
    let dir = temp_dir("reduce-wafer-files");
    let grid = hinf_grid(&[&m], 100);
    let peak = max_sv_difference(
        &m,
        &ModalModel {
            rigid: vec![],
            ..m.clone()
        },
        &grid,
    )
    .unwrap();
    for (domain, name) in [
        (Domain::Continuous, "c.json"),
        (Domain::ZohDiscrete { ts: 1e-4 }, "zoh.json"),
    ] {
        let back = modal_of(&model_file(&m, domain, &dir.join(name)));
        assert_same_rigid(&back, &m, if name == "c.json" { 0.0 } else { 1e-13 });
        let d = max_sv_difference(&m, &back, &grid).unwrap();
        assert!(d <= 1e-10 * peak, "{name}: {d:.3e} of {peak:.3e}");
    }
}

fn run_ok(args: &[&str]) -> String {
    let o = run(args);
    assert!(o.status.success(), "{args:?}: {}", stderr(&o));
    stdout(&o)
}

/// The 2 x 3 plant of the CLI tests ([`common::plant`]) with a feedthrough.
fn plant_with_feedthrough() -> ModalModel {
    let mut m = common::plant();
    let (ny, nu) = (2, 3);
    m.feedthrough = Mat::from_fn(ny, nu, |i, j| 1e-3 * (i as f64 - j as f64));
    m
}

fn reduce_cli(model: &Path, out: &Path, order: usize) -> (String, ModelFile) {
    let s = run_ok(&[
        "reduce",
        model.to_str().unwrap(),
        "--order",
        &order.to_string(),
        "--out",
        out.to_str().unwrap(),
    ]);
    (s, ModelFile::read(out).unwrap())
}

fn check_cli_reduction(m: &ModalModel, model: &Path, dir: &Path, orders: &[usize], rigid_tol: f64) {
    for &order in orders {
        let out: PathBuf = dir.join(format!("r{order}.json"));
        let (text, r) = reduce_cli(model, &out, order);
        assert!(text.contains("a-priori bound"), "{text}");
        let hsv = r
            .provenance
            .hankel_singular_values
            .clone()
            .expect("HSVs in the provenance");
        let bound = r.provenance.error_bound.expect("bound in the provenance");
        let an = BalancedTruncation::default().analyse(m).unwrap();
        assert_eq!(hsv.len(), an.stable_order);
        let kept = order - an.rigid_order;
        let expect = 2.0 * hsv[kept..].iter().sum::<f64>();
        assert!(
            (bound - expect).abs() <= 1e-12 * expect.max(1e-300),
            "{bound} vs {expect}"
        );
        let red = modal_of(&r);
        assert_same_rigid(&red, m, rigid_tol);
        let grid = hinf_grid(&[m, &red], 300);
        let err = max_sv_difference(m, &red, &grid).unwrap();
        println!(
            "{}: order {order}: measured {err:.4e}, bound {bound:.4e}",
            model.display()
        );
        assert!(
            err <= bound * (1.0 + 1e-6) + 1e-9 * hsv[0],
            "order {order}: {err:.6e} > {bound:.6e}"
        );
        assert!(r.provenance.estimator.starts_with("balanced truncation"));
    }
}

#[test]
fn cli_reduce_writes_the_bound_and_keeps_the_integrators() {
    let dir = temp_dir("reduce-cli");
    let m = plant_with_feedthrough();
    for (domain, name, rigid_tol) in [
        (Domain::Continuous, "m.json", 0.0),
        (Domain::ZohDiscrete { ts: 1e-3 }, "mz.json", 1e-13),
    ] {
        let path = dir.join(name);
        model_file(&m, domain, &path);
        // no order: the table, nothing written
        let s = run_ok(&["reduce", path.to_str().unwrap()]);
        assert!(s.contains("4 rigid-body") && s.contains("6 stable"), "{s}");
        assert!(s.contains("Hankel"), "{s}");
        check_cli_reduction(&m, &path, &dir, &[6, 8, 10], rigid_tol);
    }
}

#[test]
fn cli_reduce_refuses_bad_orders_and_files() {
    let dir = temp_dir("reduce-bad");
    let path = dir.join("m.json");
    model_file(&plant_with_feedthrough(), Domain::Continuous, &path);
    let out = dir.join("r.json");
    for (order, says) in [("11", "at most 10"), ("3", "at least 4"), ("0", "at least")] {
        let o = run(&[
            "reduce",
            path.to_str().unwrap(),
            "--order",
            order,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(!o.status.success());
        let e = stderr(&o);
        assert!(e.contains("--order") && e.contains(says), "{order}: {e}");
        assert!(!out.exists(), "written despite the error");
    }
    for bad in [
        vec!["--order", "-2"],
        vec!["--order", "x"],
        vec!["--order", "6"],
    ] {
        let mut args = vec!["reduce", path.to_str().unwrap()];
        args.extend(bad.iter().copied());
        let o = run(&args);
        assert!(!o.status.success(), "{bad:?}");
        assert!(!stderr(&o).is_empty());
    }
    let o = run(&["reduce", dir.join("missing.json").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("missing.json"), "{}", stderr(&o));
}
