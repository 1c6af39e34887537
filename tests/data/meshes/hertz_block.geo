// Hertz validation (docs/validation.md): the elastic half-space as a 100 x 100 x 50 mm block,
// top face z = 0 centred on the origin, bottom clamped. Elements are refined towards the
// contact point: Mesh.MeshSizeMax / 16 within 3 mm of the origin, growing to Mesh.MeshSizeMax
// at 40 mm (the scene's mesh_size is Mesh.MeshSizeMax). Lengths in mm.
// Groups: "block" (volume), "bottom" (clamped), "contact" (a disc of radius 4 mm of the top
// face around the origin: the only faces the indenter reaches, which keeps the dense contact
// compliance small; at the deepest press, 0.4 mm, the sphere overlaps the plane within
// (2 R d)^1/2 = 2.8 mm and the Hertz contact radius is 2 mm).
SetFactory("OpenCASCADE");
Box(1) = {-50, -50, -50, 100, 100, 50};
Disk(10) = {0, 0, 0, 4};
BooleanFragments{ Volume{1}; Delete; }{ Surface{10}; Delete; }
Point(100) = {0, 0, 0};
Point{100} In Surface{10};
h = Mesh.MeshSizeMax;
Field[1] = Distance;
Field[1].PointsList = {100};
Field[2] = Threshold;
Field[2].InField = 1;
Field[2].SizeMin = h / 16;
Field[2].SizeMax = h;
Field[2].DistMin = 3;
Field[2].DistMax = 40;
Background Field = 2;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
Physical Volume("block") = {1};
Physical Surface("bottom") = Surface In BoundingBox{-50.1, -50.1, -50.1, 50.1, 50.1, -49.9};
Physical Surface("contact") = Surface In BoundingBox{-4.1, -4.1, -0.1, 4.1, 4.1, 0.1};
