//! What the user sees of a render: [`report`] holds the warnings printed while it runs, the worker table and
//! the summary line at the end; [`live`] serves a web page of the render while it runs (`render --serve`).

pub mod live;
pub mod report;
