"""Survey walks per map cell, and the residuals' robust spread."""
import os,sys,glob,numpy as np
sys.path.insert(0,os.path.dirname(os.path.abspath(__file__))); from analysis import *
for fl in ['B1','F2']:
    fs=sorted(glob.glob(f'{C}/{fl}/*.npz')); walks=[load_walk(f) for f in fs]
    test=[w for i,w in enumerate(walks) if i%5==4 and w]; surv=[w for i,w in enumerate(walks) if i%5!=4 and w]
    for c in [1.,2.]:
        g,per,n,S,SS=build_maps(surv,c); mp=Map(g,n,S,SS)
        # how many walks per valid cell; across-walk std of per-walk cell means
        nw=sum((p[0]>=3).astype(int) for p in per.values())
        cm=np.stack([np.where(p[0]>=3,p[1][:,0]/np.maximum(p[0],1),np.nan) for p in per.values()])
        with np.errstate(all='ignore'): acs=np.nanstd(cm,0)
        m=nw>=3
        print(fl,c,'cells',mp.valid.sum(),'walks/cell p50',np.median(nw[mp.valid]),'across-walk std of cell mean |B| (cells>=3 walks) p50',np.nanmedian(acs[m]))
        for W in [2.]:
            R=[];Rp=[]
            for w in test:
                e=epochs(w,W)
                if e is None: continue
                O,Pm=e; mt=mp.lookup(Pm)
                # path-averaged map: lookup at each sample, average within epoch
                t=w['t']; k=((t-t[0])//(W*1000)).astype(int)
                ms=mp.lookup(w['P'])[:,0]
                nE=int((t[-1]-t[0])//(W*1000)); pa=np.array([np.nanmean(ms[k==i]) if np.any(~np.isnan(ms[k==i])) else np.nan for i in range(nE)])
                cnt=np.bincount(k,minlength=nE+1)[:nE]; pa=pa[cnt>=W*25]
                r=O[:,0]-mt[:,0]; R.append(r); Rp.append(O[:,0]-pa)
            R=np.concatenate(R); R=R[~np.isnan(R)]; Rp=np.concatenate(Rp); Rp=Rp[~np.isnan(Rp)]
            for nm,x in [('mid',R),('pathavg',Rp)]:
                print('  W',W,nm,'n',len(x),'std %.2f robust %.2f'%(x.std(),1.4826*np.median(np.abs(x-np.median(x)))),'abs q50/90/99',np.percentile(np.abs(x),[50,90,99]).round(2))
