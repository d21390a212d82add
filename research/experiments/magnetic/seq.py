"""Sequence-matching upper bound: 10 m stretches of test walks, obs profile (1 m bins along path) vs map along truth path and shifted paths."""
import os,sys,glob,json,numpy as np
sys.path.insert(0,os.path.dirname(os.path.abspath(__file__))); from analysis import *
SH=[3,5,10]; L=10.; BIN=1.; STEP=5.
out={}; pooled={}
for c in [1.,2.]:
  for fl in FLOORS:
    fs=sorted(glob.glob(f'{C}/{fl}/*.npz')); walks=[load_walk(f) for f in fs]
    test=[w for i,w in enumerate(walks) if i%5==4 and w]; surv=[w for i,w in enumerate(walks) if i%5!=4 and w]
    g,per,n,S,SS=build_maps(surv,c); mp=Map(g,n,S,SS)
    recs=[]
    for w in test:
        P=w['P']; F=w['F']; d=np.concatenate([[0],np.cumsum(np.hypot(*np.diff(P,axis=0).T))])
        mt=mp.lookup(P); ok=~np.isnan(mt[:,0])
        if ok.sum()<50: continue
        off=(F[ok]-mt[ok]).mean(0)   # full-walk offset (sample level)
        for s0 in np.arange(0,d[-1]-L+1e-9,STEP):
            sel=(d>=s0)&(d<s0+L); b=((d[sel]-s0)//BIN).astype(int); nb=int(L/BIN)
            cnt=np.bincount(b,minlength=nb)
            if (cnt==0).any(): continue
            Ob=np.stack([np.bincount(b,F[sel,i],minlength=nb) for i in range(3)],1)/cnt[:,None]
            Pb=np.stack([np.bincount(b,P[sel,i],minlength=nb) for i in range(2)],1)/cnt[:,None]
            u=Pb[-1]-Pb[0]; nu=np.linalg.norm(u)
            if nu<3: continue   # stretch folds back on itself
            u/=nu; o=np.array([-u[1],u[0]])
            shifts=[(0,'truth',np.zeros(2))]+[(s,f'{k}{sg*s:+d}',sg*s*vec) for s in SH for k,vec in [('along',u),('orth',o)] for sg in [1,-1]]
            costs={}
            for s,name,v in shifts:
                M=mp.lookup(Pb+v); val=~np.isnan(M[:,0])
                if val.sum()<0.8*nb: continue
                for fsn,fi in [('mag',[0]),('v+h',[1,2])]:
                    dO=Ob[val][:,fi]; dM=M[val][:,fi]
                    costs[(name,s,fsn,'raw')]=np.sqrt(np.mean((dO-dM)**2))
                    costs[(name,s,fsn,'walkoff')]=np.sqrt(np.mean((dO-off[fi]-dM)**2))
                    costs[(name,s,fsn,'demean')]=np.sqrt(np.mean(((dO-dO.mean(0))-(dM-dM.mean(0)))**2))
            if ('truth',0,'mag','raw') in costs: recs.append(costs)
    for r in recs: pooled.setdefault(c,[]).append(r)
    out[f'{fl}_c{c}']=recs
def summar(recs):
    s={}
    for fsn in ['mag','v+h']:
        for cond in ['raw','walkoff','demean']:
            row={'nstretch':len(recs)}
            tr=np.array([r[('truth',0,fsn,cond)] for r in recs]); row['rms_truth_med']=float(np.median(tr))
            for sh in SH:
                win=[];rat=[]
                for r in recs:
                    for k,v in r.items():
                        if k[1]==sh and k[2]==fsn and k[3]==cond:
                            win.append(r[('truth',0,fsn,cond)]<v); rat.append(v/r[('truth',0,fsn,cond)])
                row[f'P(truth<shift{sh})']=float(np.mean(win)) if win else None
                row[f'medratio{sh}']=float(np.median(rat)) if rat else None
            best=[];
            for r in recs:
                alts=[v for k,v in r.items() if k[0]!='truth' and k[2]==fsn and k[3]==cond]
                if alts: best.append(r[('truth',0,fsn,cond)]<min(alts))
            row['P(truth best of all)']=float(np.mean(best)); row['n_with_alts']=len(best)
            s[f'{fsn}|{cond}']=row
    return s
res={k:summar(v) for k,v in out.items() if v}
res.update({f'pooled_c{c}':summar(v) for c,v in pooled.items()})
json.dump(res,open('target/magnetic/seq_results.json','w'),indent=1)
for k,v in res.items():
    print(k)
    for kk,row in v.items(): print('  ',kk,{a:(round(b,2) if isinstance(b,float) else b) for a,b in row.items()})
