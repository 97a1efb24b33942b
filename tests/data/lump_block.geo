// A 10 x 10 x 5 cm block (top face z = 0) with a spherical lump of radius 1 cm centred 2 cm
// below the top, meshed conformally: physical volumes "matrix" and "lump", physical surface
// "bottom". For tests/material_field_test.cpp (group inclusions). Regenerate with
// scripts/make_test_meshes.sh.
SetFactory("OpenCASCADE");
Box(1) = {-0.05, -0.05, -0.05, 0.1, 0.1, 0.05};
Sphere(2) = {0, 0, -0.02, 0.01};
BooleanFragments{ Volume{1}; Delete; }{ Volume{2}; Delete; }
eps = 1e-4;
lump() = Volume In BoundingBox{-0.01 - eps, -0.01 - eps, -0.03 - eps, 0.01 + eps, 0.01 + eps, -0.01 + eps};
all() = Volume{:};
matrix() = all();
matrix() -= lump();
bottom() = Surface In BoundingBox{-0.05 - eps, -0.05 - eps, -0.05 - eps, 0.05 + eps, 0.05 + eps, -0.05 + eps};
Physical Volume("matrix", 1) = matrix();
Physical Volume("lump", 2) = lump();
Physical Surface("bottom", 3) = bottom();
MeshSize{ PointsOf{ Volume{lump()}; } } = 0.003;  // the lump resolved: six spacings across its radius (6.3)
Mesh.CharacteristicLengthMax = 0.012;
Mesh.CharacteristicLengthMin = 0.004;
Mesh.MshFileVersion = 4.1;
Mesh.Binary = 0;
