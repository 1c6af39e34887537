// A soft organ resting on a rigid table: the upper half of an ellipsoid with semi-axes
// 40 x 25 x 15 mm; its flat base (z = 0) is clamped. Lengths in mm (scenes give
// length_unit_m: 0.001). Physical groups: "organ" (volume), "base" (clamped), "skin" (the
// curved surface that may touch). Meshed by Gmsh at load with the scene's mesh_size.
SetFactory("OpenCASCADE");
Sphere(1) = {0, 0, 0, 1};
Dilate {{0, 0, 0}, {40, 25, 15}} { Volume{1}; }
Box(2) = {-50, -50, -30, 100, 100, 30};
BooleanDifference(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Physical Volume("organ") = {3};
base[] = Surface In BoundingBox{-41, -26, -0.01, 41, 26, 0.01};
all[] = Abs(Boundary{ Volume{3}; });
skin[] = all[];
skin[] -= base[];
Physical Surface("base") = {base[]};
Physical Surface("skin") = {skin[]};
