"""Reads the competition walks in target/ilc/site1 into target/magnetic/cache, one .npz per walk."""
import os, sys, glob, numpy as np
from multiprocessing import Pool
ROOT='target/ilc/site1'
OUT='target/magnetic/cache'
KEEP={'TYPE_WAYPOINT':'wp','TYPE_MAGNETIC_FIELD':'mag','TYPE_ACCELEROMETER':'acc','TYPE_ROTATION_VECTOR':'rv',
      'TYPE_MAGNETIC_FIELD_UNCALIBRATED':'magu','TYPE_SENSOR_MAGNETIC_FIELD_ACCURACY_CHANGED':'macc'}
def parse(args):
    floor,fn=args
    d={v:[] for v in KEEP.values()}; model=''
    with open(fn,encoding='utf-8',errors='replace') as f:
        for line in f:
            if line[0]=='#':
                if 'Model:' in line:
                    model=' '.join(p for p in line.strip().split('\t') if p.startswith(('Brand','Model','AndroidName')))
                continue
            p=line.rstrip('\n').split('\t')
            if len(p)<2: continue
            k=KEEP.get(p[1])
            if k is None: continue
            try:
                vals=[float(p[0])]+[float(x) for x in p[2:] if x!='']
            except ValueError: continue
            d[k].append(vals)
    out={}
    for k,v in d.items():
        if not v: out[k]=np.zeros((0,1)); continue
        n=min(len(r) for r in v); out[k]=np.array([r[:n] for r in v])
    name=os.path.basename(fn)[:-4]
    os.makedirs(f'{OUT}/{floor}',exist_ok=True)
    np.savez(f'{OUT}/{floor}/{name}.npz',model=model,**out)
    return floor,name,len(d['mag']),len(d['wp'])
if __name__=='__main__':
    jobs=[(fl,fn) for fl in ['B1','F1','F2','F3','F4'] for fn in sorted(glob.glob(f'{ROOT}/{fl}/path_data_files/*.txt'))]
    with Pool(2) as p:
        for r in p.imap_unordered(parse,jobs,chunksize=4): pass
    print('done',len(jobs))
