"""The output stage: the files `lfcl process` writes, refocusing, and the sRGB previews."""
