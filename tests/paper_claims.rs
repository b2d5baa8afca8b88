//! The paper's qualitative claims, on few fixed seeds.
