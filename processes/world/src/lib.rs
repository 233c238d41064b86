//! World simulation: scenarios, unicycle dynamics, contact resolution, ground truth
