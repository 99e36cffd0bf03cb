//! Texel lightmaps on TEXCOORD_1 or a generated chart atlas (DESIGN.md §3.3). (In progress.)
