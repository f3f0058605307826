//! SVG figures (plotters, SVG backend only): the CMIF with picked modes, Bode magnitude
//! grids of data and model, one entry with data, model and residual against the noise.
