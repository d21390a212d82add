"""Per floor and pooled: walk offsets, residual spreads, map contrast and per-epoch log-likelihood ratios (arguments: cell sizes, epoch lengths)."""
import os, sys, json, numpy as np, glob
sys.path.insert(0,os.path.dirname(os.path.abspath(__file__))); from analysis import *
CS=[float(x) for x in (sys.argv[1] if len(sys.argv)>1 else '1,2').split(',')]
WS=[float(x) for x in (sys.argv[2] if len(sys.argv)>2 else '2,0.5').split(',')]
res={}
def corrected(r_list,O_list,G):
    """yield per-walk corrected obs for each condition"""
    pass
def llr_stats(recs,sig,cond,G,fi):
    """recs: list of walk records; fi: list of feature indices; returns dict ring->array of per-epoch mean LLR"""
    out={}
    for ring in RINGS:
        L=[]
        for r in recs:
            O=r['O'].copy(); mt=r['mt']; res_=O-mt; n=len(O)
            if cond=='full': off=np.tile(res_.mean(0),(n,1))
            elif cond=='causal_truth':
                cs=np.vstack([np.zeros((1,3)),np.cumsum(res_,0)[:-1]]); off=cs/np.maximum(np.arange(n),1)[:,None]
            elif cond=='causal_blind':
                cs=np.vstack([np.zeros((1,3)),np.cumsum(O,0)[:-1]]); off=cs/np.maximum(np.arange(n),1)[:,None]-G[None]
                off[0]=0
            else: off=np.zeros((n,3))
            Oc=O-off; mc=r['cands'][ring]
            e_t=np.sum(((Oc-mt)[:,fi]/sig[fi])**2,1)/2
            e_j=np.sum(((Oc[:,None,:]-mc)[:,:,fi]/sig[fi])**2,2)/2   # nan where cand invalid
            llr=np.nanmean(e_j-e_t[:,None],1)
            L.append(llr[~np.isnan(llr)])
        out[ring]=np.concatenate(L) if L else np.array([])
    return out

def cond_resid(recs,cond,G):
    R=[]
    for r in recs:
        O=r['O']; res_=O-r['mt']; n=len(O)
        if cond=='full': res_=res_-res_.mean(0)
        elif cond=='causal_truth':
            cs=np.vstack([np.zeros((1,3)),np.cumsum(res_,0)[:-1]]); res_=res_-cs/np.maximum(np.arange(n),1)[:,None]
        elif cond=='causal_blind':
            cs=np.vstack([np.zeros((1,3)),np.cumsum(O,0)[:-1]]); off=cs/np.maximum(np.arange(n),1)[:,None]-G[None]; off[0]=0
            res_=res_-off
        R.append(res_)
    return np.vstack(R)

CONDS=['raw','full','causal_truth','causal_blind']
FSETS={'mag':[0],'vert':[1],'horiz':[2],'v+h':[1,2]}
pooled={}
allwalks={}
for fl in FLOORS:
    fs=sorted(glob.glob(f'{C}/{fl}/*.npz'))
    walks=[load_walk(f) for f in fs]
    test=[w for i,w in enumerate(walks) if i%5==4 and w is not None]
    surv=[w for i,w in enumerate(walks) if i%5!=4 and w is not None]
    allwalks[fl]=(surv,test)
    # cross-check vertical from accel vs rotvec
    va=np.concatenate([w['F'][:,1] for w in surv]); vr=np.concatenate([w['vrv'] for w in surv])
    res.setdefault('vcheck',{})[fl]=dict(corr=float(np.corrcoef(va,vr)[0,1]),mad=float(np.median(np.abs(va-vr))))
    for c in CS:
        g,per,n,S,SS=build_maps(surv,c)
        mp=Map(g,n,S,SS)
        G=np.nansum(S,0)/n.sum()
        # map cell stats
        cellstd=mp.std[mp.valid]; 
        res.setdefault('cells',{})[f'{fl}_c{c}']=dict(ncells=int(mp.valid.sum()),med_count=float(np.median(n[mp.valid])),med_cell_std=np.median(cellstd,0).tolist())
        for W in WS:
            key=f'{fl}_c{c}_W{W}'
            T=[];
            for w in test:
                e=epochs(w,W)
                if e is None: continue
                a=analyse_walk(mp,*e)
                if len(a['O'])>0: a['name']=w['name']; T.append(a)
            Lrecs=[]
            for w in surv:
                e=epochs(w,W)
                if e is None: continue
                pn=per[w['name']]; m2=Map(g,n-pn[0],S-pn[1],SS-pn[2])
                a=analyse_walk(m2,*e)
                if len(a['O'])>0: a['name']=w['name']; Lrecs.append(a)
            for setname,recs in [('test',T),('loo',Lrecs)]:
                if not recs: continue
                d={}
                offs=np.array([ (r['O']-r['mt']).mean(0) for r in recs]); nep=np.array([len(r['O']) for r in recs])
                d['nwalks']=len(recs); d['nepochs']=int(nep.sum())
                d['offset']={f:q(offs[:,i]) for i,f in enumerate(FEAT)}
                d['offset_w5']={f:q(offs[nep>=5,i]) for i,f in enumerate(FEAT)} if (nep>=5).sum()>2 else None
                sig={cnd:cond_resid(recs,cnd,G).std(0) for cnd in CONDS}
                d['resid_std']={cnd:dict(zip(FEAT,sig[cnd].tolist())) for cnd in CONDS}
                # spatial variability
                sv=[];ad=[]
                for r in recs:
                    with np.errstate(all='ignore'):
                        sv.append(np.nanstd(r['cands'][(2,8)],1)); ad.append(np.nanmean(np.abs(r['cands'][(3,6)]-r['mt'][:,None,:]),1))
                sv=np.vstack(sv); ad=np.vstack(ad)
                d['spatial_std_2_8_med']=dict(zip(FEAT,np.nanmedian(sv,0).tolist()))
                d['absdiff_3_6_med']=dict(zip(FEAT,np.nanmedian(ad,0).tolist()))
                d['absdiff_3_6_mean']=dict(zip(FEAT,np.nanmean(ad,0).tolist()))
                d['llr']={}
                for cnd in CONDS:
                    for fsn,fi in FSETS.items():
                        L=llr_stats(recs,sig[cnd],cnd,G,fi)
                        d['llr'][f'{cnd}|{fsn}']={f'{a}-{b}':dict(mean=float(L[(a,b)].mean()),med=float(np.median(L[(a,b)])),fpos=float((L[(a,b)]>0).mean())) for (a,b) in RINGS}
                        pooled.setdefault((setname,c,W,cnd,fsn),{}).setdefault('L',[]).append(L)
                pk=(setname,c,W)
                pooled.setdefault(pk,{'offs':[],'sv':[],'ad':[],'rraw':[],'rfull':[],'rct':[],'rcb':[]})
                P=pooled[pk]; P['offs'].append(offs); P['sv'].append(sv); P['ad'].append(ad)
                P['rraw'].append(cond_resid(recs,'raw',G)); P['rfull'].append(cond_resid(recs,'full',G))
                P['rct'].append(cond_resid(recs,'causal_truth',G)); P['rcb'].append(cond_resid(recs,'causal_blind',G))
                res.setdefault(setname,{})[key]=d
            print(key,len(T),len(Lrecs),flush=True)
# pooled
pr={}
for k,v in pooled.items():
    if len(k)==3:
        offs=np.vstack(v['offs']); sv=np.vstack(v['sv']); ad=np.vstack(v['ad'])
        pr[f'{k[0]}_c{k[1]}_W{k[2]}']=dict(offset={f:q(offs[:,i]) for i,f in enumerate(FEAT)},
            resid_std={nm:dict(zip(FEAT,np.vstack(v[nm]).std(0).tolist())) for nm in ['rraw','rfull','rct','rcb']},
            spatial_std_2_8_med=dict(zip(FEAT,np.nanmedian(sv,0).tolist())),absdiff_3_6_med=dict(zip(FEAT,np.nanmedian(ad,0).tolist())))
for k,v in pooled.items():
    if len(k)==5:
        s,c,W,cnd,fsn=k; key=f'{s}_c{c}_W{W}'
        pr.setdefault(key,{}).setdefault('llr',{})[f'{cnd}|{fsn}']={f'{a}-{b}':(lambda L:dict(mean=float(L.mean()),med=float(np.median(L)),fpos=float((L>0).mean())))(np.concatenate([x[(a,b)] for x in v['L']])) for (a,b) in RINGS}
res['pooled']=pr
json.dump(res,open(f'target/magnetic/results_{"_".join(map(str,CS))}_{"_".join(map(str,WS))}.json','w'),indent=1)
print('saved')
