//! Curves and rows shared by the unit tests of several modules.

use crate::budget::{Budget, Row};
use crate::curve::Curve;
use photon_core::method::Method;

/// A curve of `path` through `points`.
pub(crate) fn curve(points: &[(f64, f64)]) -> Curve {
    Curve { method: Method::Path, points: points.to_vec() }
}

/// A row at 4·`budget` spp.
pub(crate) fn row(method: Method, budget: u32, seconds: f64, rel_mse: f64) -> Row {
    let setting = Budget { parameter: "spp", value: u64::from(4 * budget) };
    Row { method, budget, setting, seconds, rmse: rel_mse.sqrt(), rel_mse, estimated_rel_mse: None }
}

/// Two methods whose time ranges overlap, so that both summaries have columns; progressive's rows out of
/// budget order.
pub(crate) fn two_methods() -> Vec<Row> {
    vec![
        row(Method::Path, 1, 1.0, 0.1),
        row(Method::Path, 4, 4.0, 0.025),
        row(Method::Progressive, 4, 8.0, 0.01),
        row(Method::Progressive, 1, 2.0, 0.08),
    ]
}
