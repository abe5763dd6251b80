"""usage: same_sets.py DIR_A DIR_B -- are the decoded PLY frames of A and B the same Gaussians (as multisets of rows)?"""
import sys; sys.path.insert(0,'/tmp/peers')
import numpy as np
from plyio import read_ply
A,B=sys.argv[1:3]; same=0; maxd=0.0
for f in range(1,201):
    a=read_ply('%s/wave_%04d.ply'%(A,f)); b=read_ply('%s/wave_%04d.ply'%(B,f))
    X=np.stack([a[k] for k in a.dtype.names],1); Y=np.stack([b[k] for k in a.dtype.names],1)
    X=X[np.lexsort(X.T[::-1])]; Y=Y[np.lexsort(Y.T[::-1])]
    d=float(np.abs(X-Y).max()); maxd=max(maxd,d); same+=(d==0)
print('%s vs %s: %d/200 frames identical, max abs diff %g'%(A,B,same,maxd))
