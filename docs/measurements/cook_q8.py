# Independent 2D plane-stress Cook's membrane with 8-node serendipity quads (3x3 Gauss).
import numpy as np, sys
E, nu = 1.0, 1.0/3.0
D = E/(1-nu**2)*np.array([[1,nu,0],[nu,1,0],[0,0,(1-nu)/2]])
def geom(s, t):  # s,t in [0,1]
    x = 48*s; y0 = 44*s; y1 = 44+16*s
    return x, y0 + t*(y1-y0)
def solve(m):
    # node grid on (2m+1)x(2m+1) lattice, skipping cell-centre points
    idx = {}; pts = []
    for i in range(2*m+1):
        for j in range(2*m+1):
            if i % 2 == 1 and j % 2 == 1: continue
            idx[(i,j)] = len(pts); pts.append(geom(i/(2*m), j/(2*m)))
    pts = np.array(pts); n = len(pts)
    K = np.zeros((2*n, 2*n)); F = np.zeros(2*n)
    # serendipity local nodes (xi,eta)
    loc = [(-1,-1),(1,-1),(1,1),(-1,1),(0,-1),(1,0),(0,1),(-1,0)]
    def shp(x, e):
        N = []; dN = []
        for (a,b) in loc:
            if a != 0 and b != 0:
                N.append(0.25*(1+a*x)*(1+b*e)*(a*x+b*e-1))
                dN.append((0.25*a*(1+b*e)*(2*a*x+b*e), 0.25*b*(1+a*x)*(a*x+2*b*e)))
            elif a == 0:
                N.append(0.5*(1-x*x)*(1+b*e)); dN.append((-x*(1+b*e), 0.5*b*(1-x*x)))
            else:
                N.append(0.5*(1+a*x)*(1-e*e)); dN.append((0.5*a*(1-e*e), -e*(1+a*x)))
        return np.array(N), np.array(dN)
    g = np.sqrt(0.6); gp = [(-g,5/9),(0,8/9),(g,5/9)]
    for i in range(m):
        for j in range(m):
            I, J = 2*i, 2*j
            nodes = [idx[(I+1+a, J+1+b)] for (a,b) in loc]
            X = pts[nodes]; dofs = np.array([[2*k,2*k+1] for k in nodes]).ravel()
            Ke = np.zeros((16,16))
            for x, wx in gp:
                for e, we in gp:
                    N, dN = shp(x, e)
                    Jm = dN.T @ X
                    dNx = np.linalg.solve(Jm, dN.T).T
                    B = np.zeros((3,16))
                    B[0,0::2] = dNx[:,0]; B[1,1::2] = dNx[:,1]
                    B[2,0::2] = dNx[:,1]; B[2,1::2] = dNx[:,0]
                    Ke += B.T @ D @ B * np.linalg.det(Jm) * wx * we
            K[np.ix_(dofs,dofs)] += Ke
    # right edge i = 2m: traction 1/16 in y, quadratic edge: consistent loads 1/6,4/6,1/6 of edge force
    for j in range(m):
        a, b, c = idx[(2*m, 2*j)], idx[(2*m, 2*j+1)], idx[(2*m, 2*j+2)]
        fe = 1.0/m  # edge of length 16/m times 1/16
        F[2*a+1] += fe/6; F[2*b+1] += 4*fe/6; F[2*c+1] += fe/6
    fixed = [2*idx[(0,j)]+c for j in range(2*m+1) if (0,j) in idx for c in (0,1)]
    free = np.setdiff1d(np.arange(2*n), fixed)
    u = np.zeros(2*n); u[free] = np.linalg.solve(K[np.ix_(free,free)], F[free])
    return u[2*idx[(2*m,2*m)]+1]
for m in [int(a) for a in sys.argv[1:]]:
    print(m, solve(m), flush=True)
