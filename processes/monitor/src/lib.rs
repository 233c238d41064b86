//! Monitor: metrics against ground truth, summary.json and map.png
