"""Shared code: walks from the cache, the magnetic features, per-floor maps and epoch aggregation (see README.md)."""
import glob, os, sys, json, numpy as np
C='target/magnetic/cache'; FLOORS=['B1','F1','F2','F3','F4']
FEAT=['mag','vert','horiz']; NMIN=5
rng=np.random.default_rng(0)

def movavg(t,x,win=1000.):
    cs=np.vstack([np.zeros((1,x.shape[1])),np.cumsum(x,0)])
    lo=np.searchsorted(t,t-win/2); hi=np.searchsorted(t,t+win/2,side='right')
    return (cs[hi]-cs[lo])/np.maximum(hi-lo,1)[:,None]

def load_walk(f):
    z=np.load(f); wp=z['wp']; mag=z['mag']; acc=z['acc']; rv=z['rv']
    if len(wp)<2 or len(mag)<10 or len(acc)<10: return None
    t=mag[:,0]; B=mag[:,1:4]
    g=movavg(acc[:,0],acc[:,1:4]); g=np.column_stack([np.interp(t,acc[:,0],g[:,i]) for i in range(3)])
    g/=np.linalg.norm(g,axis=1,keepdims=True)
    m=np.linalg.norm(B,axis=1); v=np.sum(B*g,1); h=np.sqrt(np.maximum(m**2-v**2,0))
    # rotation-vector vertical (world z row of R) for cross-check
    q=np.column_stack([np.interp(t,rv[:,0],rv[:,i]) for i in range(1,4)])
    w=np.sqrt(np.clip(1-np.sum(q**2,1),0,1)); x,y,zz=q.T
    Rz=np.column_stack([2*(x*zz-w*y),2*(y*zz+w*x),1-2*(x*x+y*y)])
    vrv=np.sum(B*Rz,1)
    sel=(t>=wp[0,0])&(t<=wp[-1,0])
    wt=wp[:,0]; px=np.interp(t,wt,wp[:,1]); py=np.interp(t,wt,wp[:,2])
    return dict(name=os.path.basename(f)[:-4],t=t[sel],F=np.column_stack([m,v,h])[sel],P=np.column_stack([px,py])[sel],
                vrv=vrv[sel],model=str(z['model']),t0=wt[0])

class Grid:
    def __init__(s,c,lo,hi):
        s.c=c; s.lo=np.floor(lo)-2; s.nx,s.ny=(np.ceil((hi-s.lo+2)/c)).astype(int)
    def idx(s,P):
        ij=np.floor((P-s.lo)/s.c).astype(int); return ij
    def flat(s,P):
        ij=s.idx(P); return ij[:,0]*s.ny+ij[:,1]
    def acc(s,w):
        k=s.flat(w['P']); N=s.nx*s.ny
        n=np.bincount(k,minlength=N).astype(float)
        S=np.stack([np.bincount(k,w['F'][:,i],minlength=N) for i in range(3)],1)
        SS=np.stack([np.bincount(k,w['F'][:,i]**2,minlength=N) for i in range(3)],1)
        return n,S,SS

class Map:
    def __init__(s,g,n,S,SS):
        s.g=g; s.n=n; s.valid=n>=NMIN
        s.mean=np.where(s.valid[:,None],S/np.maximum(n,1)[:,None],np.nan)
        s.std=np.sqrt(np.maximum(SS/np.maximum(n,1)[:,None]-s.mean**2,0))
        s.M=s.mean.reshape(g.nx,g.ny,3); s.V=s.valid.reshape(g.nx,g.ny)
    def lookup(s,P):
        """map features at points P: containing cell if valid, else nearest valid cell whose rectangle is within 1 m"""
        g=s.g; ij=g.idx(P); out=np.full((len(P),3),np.nan); best=np.full(len(P),np.inf)
        r=int(np.ceil(1.0/g.c))
        for di in range(-r,r+1):
            for dj in range(-r,r+1):
                ii=ij[:,0]+di; jj=ij[:,1]+dj
                ok=(ii>=0)&(ii<g.nx)&(jj>=0)&(jj<g.ny)
                ii=np.clip(ii,0,g.nx-1); jj=np.clip(jj,0,g.ny-1)
                x0=g.lo[0]+ii*g.c; y0=g.lo[1]+jj*g.c
                dx=np.maximum.reduce([x0-P[:,0],np.zeros(len(P)),P[:,0]-x0-g.c])
                dy=np.maximum.reduce([y0-P[:,1],np.zeros(len(P)),P[:,1]-y0-g.c])
                d=np.hypot(dx,dy); ok&=s.V[ii,jj]&(d<=1.0)&(d<best)
                out[ok]=s.M[ii[ok],jj[ok]]; best[ok]=d[ok]
        return out

def epochs(w,W):
    t=w['t']; T0=t[0]; nE=int((t[-1]-T0)//(W*1000))
    if nE<1: return None
    k=((t-T0)//(W*1000)).astype(int); sel=k<nE; k=k[sel]
    cnt=np.bincount(k,minlength=nE)
    O=np.stack([np.bincount(k,w['F'][sel,i],minlength=nE) for i in range(3)],1)/np.maximum(cnt,1)[:,None]
    tm=T0+(np.arange(nE)+0.5)*W*1000
    # truth at mid time: interpolate sample positions
    Pm=np.column_stack([np.interp(tm,t,w['P'][:,i]) for i in range(2)])
    ok=cnt>=W*50*0.5
    return O[ok],Pm[ok]

def ring_offsets(c,lo,hi):
    r=int(np.ceil(hi/c)); a=np.arange(-r,r+1)*c; X,Y=np.meshgrid(a,a); d=np.hypot(X,Y); m=(d>=lo)&(d<hi)
    return np.column_stack([X[m],Y[m]])

RINGS=[(2,4),(4,8),(8,16)]
def analyse_walk(mp,O,Pm):
    """returns per-epoch dict: obs, map at truth, candidates per ring (list of arrays n_epoch x n_cand x 3)"""
    mt=mp.lookup(Pm); ok=~np.isnan(mt[:,0])
    O,Pm,mt=O[ok],Pm[ok],mt[ok]
    cands={}
    for (a,b) in RINGS+[(2,8),(3,6)]:
        off=ring_offsets(mp.g.c,a,b)
        Q=(Pm[:,None,:]+off[None]).reshape(-1,2)
        cands[(a,b)]=mp.lookup(Q).reshape(len(Pm),len(off),3)
    return dict(O=O,mt=mt,P=Pm,cands=cands)

def build_maps(walks,c):
    allP=np.vstack([w['P'] for w in walks]); g=Grid(c,allP.min(0),allP.max(0))
    per={w['name']:g.acc(w) for w in walks}
    n=sum(p[0] for p in per.values()); S=sum(p[1] for p in per.values()); SS=sum(p[2] for p in per.values())
    return g,per,n,S,SS

def q(x): x=np.asarray(x); return dict(n=len(x),mean=float(np.mean(x)),std=float(np.std(x)),p10=float(np.percentile(x,10)),p50=float(np.percentile(x,50)),p90=float(np.percentile(x,90)))
