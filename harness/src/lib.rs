#![doc = include_str!("../README.md")]

pub mod accuracy;
pub mod bake;
pub mod baselines;
pub mod chart;
pub mod export;
pub mod gltf;
pub mod images;
pub mod io;
pub mod methods;
pub mod npz;
pub mod reference;
pub mod report;
pub mod run;
pub mod scenes;
pub mod score;
pub mod suite;
