"""Reading and writing files: raw decode, image writing (EXR/TIFF/PNG), the LinearRaw DNG."""
