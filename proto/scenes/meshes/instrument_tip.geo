// A rounded instrument tip: a cylinder of radius 4 mm, 20 mm long along z, ending in a
// hemisphere. Placed above the pole of organ.geo's dome (z = 15 mm) with a 0.2 mm gap.
// Lengths in mm. Physical groups: "tip" (volume), "handle" (the top disk, driven by the
// device), "surface" (everything else: the faces that may touch).
SetFactory("OpenCASCADE");
Cylinder(1) = {0, 0, 19.2, 0, 0, 20, 4};
Sphere(2) = {0, 0, 19.2, 4};
BooleanUnion(3) = { Volume{1}; Delete; }{ Volume{2}; Delete; };
Physical Volume("tip") = {3};
handle[] = Surface In BoundingBox{-4.1, -4.1, 39.19, 4.1, 4.1, 39.21};
all[] = Abs(Boundary{ Volume{3}; });
surface[] = all[];
surface[] -= handle[];
Physical Surface("handle") = {handle[]};
Physical Surface("surface") = {surface[]};
