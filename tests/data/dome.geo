// A hemispherical dome of radius 0.05 m on the plane z = 0 (pole at z = 0.05 m),
// for tests/mesh_reader_test.cpp. Regenerate with scripts/make_test_meshes.sh.
SetFactory("OpenCASCADE");
radius = 0.05;
Sphere(1) = {0, 0, 0, radius, 0, Pi / 2, 2 * Pi};
eps = 1e-6;
base() = Surface In BoundingBox{-radius - eps, -radius - eps, -eps, radius + eps, radius + eps, eps};
all() = Boundary{ Volume{1}; };
skin() = all();
skin() -= base();
Physical Surface("base", 1) = base();
Physical Surface("skin", 2) = skin();
Physical Volume("tissue", 3) = {1};
Mesh.CharacteristicLengthMax = 0.012;
Mesh.MshFileVersion = 4.1;
Mesh.Binary = 0;
