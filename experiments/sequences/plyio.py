import numpy as np
def read_ply(path):
    raw = open(path,'rb').read()
    end = raw.find(b"end_header"); start = raw.index(b"\n", end)+1
    hdr = raw[:end].decode().splitlines()
    n=0; props=[]
    for l in hdr:
        p=l.split()
        if p[:2]==['element','vertex']: n=int(p[2])
        elif p and p[0]=='property': props.append(p[2])
    dt=np.dtype([(k,'<f4') for k in props])
    return np.frombuffer(raw,dtype=dt,count=n,offset=start)
NAMES=['x','y','z','f_dc_0','f_dc_1','f_dc_2','opacity','scale_0','scale_1','scale_2','rot_0','rot_1','rot_2','rot_3']
def write_ply(path, cols):
    n=len(cols['x'])
    dt=np.dtype([(k,'<f4') for k in NAMES])
    a=np.empty(n,dtype=dt)
    for k in NAMES: a[k]=cols[k]
    hdr="ply\nformat binary_little_endian 1.0\nelement vertex %d\n"%n + "".join("property float %s\n"%k for k in NAMES)+"end_header\n"
    with open(path,'wb') as f:
        f.write(hdr.encode()); f.write(a.tobytes())
