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
// The organ_tip reference (docs/free-interaction.md, "Quadratic faces"): proto/scenes/meshes/
// organ.geo refined to FINE mm (Tet10 edge) where the tip goes: x from -9 to 21 mm, |y| < 8 mm,
// z above 6 mm, with a 4 mm transition. At 0.75 mm the organ has ~206 000 dofs.
FINE = DefineNumber[0.75, Name "fine"];
Field[1] = Box;
Field[1].VIn = FINE;
Field[1].VOut = 100;
Field[1].XMin = -9; Field[1].XMax = 21;
Field[1].YMin = -8; Field[1].YMax = 8;
Field[1].ZMin = 6; Field[1].ZMax = 16;
Field[1].Thickness = 4;
Background Field = 1;
