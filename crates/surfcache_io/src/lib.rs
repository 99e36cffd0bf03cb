//! glTF import/export and OpenEXR environment maps and textures.
