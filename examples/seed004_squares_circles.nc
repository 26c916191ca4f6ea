%
(squares-and-circles verification program: a square and a circle, as in laser deposition welding)
(millimetres, absolute machine coordinates, XY plane; servod maps X Y Z to servo axes 0 1 2)
(at servod's default scale, 1 mm = 1000 increments = 0.1 rev of the emulated axes)
G21 G90 G17
G1 X0 Y0 Z0 F3000          (from wherever the axes hold to the origin)
(20 mm square, G1 at 2000 mm/min = 33.3 mm/s)
G1 X20 Y0 F2000
G1 X20 Y20
G1 X0 Y20
G1 X0 Y0
(10 mm circle centred at X10 Y10: full circle clockwise, G2 at 1500 mm/min = 25 mm/s)
G1 X5 Y10 F3000
G2 X5 Y10 I5 J0 F1500
(the same circle counter-clockwise, G3 at 3000 mm/min = 50 mm/s)
G3 X5 Y10 I5 J0 F3000
(back to the origin: the program's end point is X0 Y0 Z0)
G1 X0 Y0 F3000
M2
