//! photon-proto: the wire protocol between coordinator and workers (render.proto, generated code, conversions).
