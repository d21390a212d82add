"""Residual autocorrelation across consecutive 2 s epochs, and whether per-walk offsets cluster by recording session (start time)."""
import os,sys,glob,numpy as np
sys.path.insert(0,os.path.dirname(os.path.abspath(__file__))); from analysis import *
c=2.; W=2.
ac={'raw':[], 'full':[]}; sess=[]
for fl in FLOORS:
    fs=sorted(glob.glob(f'{C}/{fl}/*.npz')); walks=[load_walk(f) for f in fs]
    test=[w for i,w in enumerate(walks) if i%5==4 and w]; surv=[w for i,w in enumerate(walks) if i%5!=4 and w]
    g,per,n,S,SS=build_maps(surv,c)
    for w in surv+test:
        if w['name'] in per: pn=per[w['name']]; mp=Map(g,n-pn[0],S-pn[1],SS-pn[2])
        else: mp=Map(g,n,S,SS)
        e=epochs(w,W)
        if e is None: continue
        mt=mp.lookup(e[1]); r=(e[0]-mt)[:,0]; r=r[~np.isnan(r)]
        if len(r)<4: continue
        sess.append((w['t0'],r.mean(),fl))
        for k,x in [('raw',r),('full',r-r.mean())]:
            ac[k].append(np.column_stack([x[:-1],x[1:]])); 
            if len(x)>2: ac.setdefault(k+'2',[]).append(np.column_stack([x[:-2],x[2:]]))
for k,v in ac.items():
    v=np.vstack(v); print('lag',k,'autocorr |B| resid %.2f'%np.corrcoef(v.T)[0,1])
sess.sort(); t=np.array([s[0] for s in sess]); o=np.array([s[1] for s in sess])
dt=np.diff(t)/60000; pairs=dt<10
print('consecutive walks <10 min apart: n=%d corr of offsets %.2f ; >=10 min: n=%d corr %.2f'%(pairs.sum(),np.corrcoef(o[:-1][pairs],o[1:][pairs])[0,1],(~pairs).sum(),np.corrcoef(o[:-1][~pairs],o[1:][~pairs])[0,1]))
days=((t-t.min())//86400000).astype(int)
for d in np.unique(days): print(' day',d,'n',(days==d).sum(),'offset mean %.1f std %.1f'%(o[days==d].mean(),o[days==d].std()))
